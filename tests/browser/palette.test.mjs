// Palette streams in the viewer (issue 18): web/palette.js's GPU synthesis in a real headless
// Chromium (software GL, the flags of viewer.test.mjs), first on synthetic streams against an
// f64 reference (no palette server needed), then against a live crease-server running its demo
// and the Rust core's own decoder (`crease decode-stream`). Plain Node ESM (node:assert +
// playwright-core): see README.md beside this file. run.sh runs it after viewer.test.mjs; alone:
//   CREASE_HTTP=127.0.0.1:PORT CREASE_TOKEN=TOKEN CREASE_BIN=target/release/crease \
//     node tests/browser/palette.test.mjs
// Env: CREASE_HTTP (host:port of the server's HTTP side, required), CREASE_TOKEN (the demo
// room's publish token, required), CREASE_BIN (the `crease` CLI; default
// ${CARGO_TARGET_DIR:-target}/release/crease), CREASE_SHOTS (screenshots; default
// ${CARGO_TARGET_DIR:-target}/browser-test), CHROMIUM (default /usr/bin/chromium),
// PALETTE_ONLY=synthetic (only the checks that need no palette server).
// Prints one line per check and the measured figures, closes on "palette: N passed, N failed";
// exits 1 on a failure.

import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";
import { LAUNCH_ARGS, capturePng, changedPixels, decodePng, imageStats, screenshotPng, watchPage, checkList, sleep, waitForCrease } from "./common.mjs";
import {
  LaneEncoder,
  baseIndices,
  cornerTurns,
  paletteLaneCount,
  paletteLanes,
  referenceMesh,
  syntheticStream,
  translationBox,
} from "./palette-synthetic.mjs";
import { PaletteDecoder, ready as codecReady } from "../../web/codec.js";
import { loopSteps } from "../../web/loop.js";
import { decodePaletteTopology } from "../../web/palette.js";
import { readMeshFrame } from "../../web/wire.js";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
const httpAddr = process.env.CREASE_HTTP;
const token = process.env.CREASE_TOKEN;
if (!httpAddr || !token) {
  console.error("FAIL: set CREASE_HTTP (host:port of crease-server's HTTP side) and CREASE_TOKEN");
  process.exit(2);
}
const base = `http://${httpAddr}`;
const target = process.env.CARGO_TARGET_DIR || "target";
const shots = path.resolve(root, process.env.CREASE_SHOTS || path.join(target, "browser-test"));
const creaseBin = path.resolve(root, process.env.CREASE_BIN || path.join(target, "release", "crease"));
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const syntheticOnly = process.env.PALETTE_ONLY === "synthetic";
const paletteVectorsPath = path.join(root, "tests/vectors/palette-v1.json");
const loopVectorsPath = path.join(root, "tests/vectors/loop-v1.json");

const VIEWPORT = { width: 1024, height: 768 };
/** GPU vs reference: the largest coordinate error allowed, as a share of the bounds' diagonal
 * (f32 rounding of the passes: ~1e-7 of the coordinates per pass). */
const RELATIVE_TOLERANCE = 1e-5;
/** The most a palette header may take to reach the page on loopback: a bound against a hang,
 * not a speed target (issue 18's detail header was 11.5 MB; issue 41's is a fraction of that). */
const HEADER_LIMIT_MS = 30_000;
/** Unit normals, GPU vs f64 reference (f32 cross products of short edges). */
const NORMAL_TOLERANCE = 1e-4;
/** A quaternion's stored error bound, core::codec::palette::ROTATION_ERROR (4 half steps). */
const ROTATION_ERROR = Math.fround((4 * Math.SQRT1_2) / 65535);
/** A pixel "differs" when a channel changed by more than this (as viewer.test.mjs). */
const PIXEL_TOLERANCE = 16;
/**
 * The share of the canvas that may differ between the vertex and the palette encoding of the
 * same frame. The geometry is the same to well under a pixel (the detail stream's 14-bit
 * quantisation step is ~6e-5 of the box, a pixel ~1.5e-3 of it), so what differs is shading:
 * the vertex path's normals come from quantised positions (on the detail level's ~0.5 mm
 * triangles a step of ~15 um tilts a normal by a degree or two: the grain on the vertex
 * screenshot), and antialiased edges. Measured 0.06% of the canvas (0.4% of the hand) with
 * SwiftShader; 0.5% leaves room for another rasteriser and is still ~1/25 of the hand.
 */
const MAX_DIFFERING_SHARE = 0.005;
const OVERALL_TIMEOUT_MS = 600_000;

// ---------------------------------------------------------------------------------------------
// Harness (common.mjs's checkList): each check runs even when an earlier one failed.

const { check, results, failed: failures, fail } = checkList();
const notes = [];
const figures = [];

/** The small, enumerable part of window.crease (not `palette`, which is hidden). */
const creaseState = (page) => page.evaluate(() => (window.crease ? JSON.parse(JSON.stringify(window.crease)) : null));

const overlay = (page) => page.evaluate(() => document.getElementById("stats").textContent);

/** {header, frame, frames, seq, readback} of the page's palette mode, in one go (the readback
 * is of that frame; frames: the messages from the last keyframe to it), as base64 (through a data: URL: the header is megabytes); waits up to 10 s for
 * a frame to be displayed (after a new header there is none until the next redraw). */
async function paletteCapture(page) {
  for (let tries = 0; tries < 100; tries++) {
    const c = await paletteCaptureNow(page);
    if (c) return c;
    await sleep(100);
  }
  return null;
}

async function paletteCaptureNow(page) {
  return page.evaluate(async () => {
    const p = window.crease.palette;
    if (!p || !p.frame) return null;
    const header = p.header;
    const frame = p.frame;
    const frames = p.frames;
    const seq = p.seq;
    const xyz = p.readback();
    const b64 = (bytes) =>
      new Promise((resolve, reject) => {
        const r = new FileReader();
        r.onload = () => resolve(String(r.result).slice(String(r.result).indexOf(",") + 1));
        r.onerror = () => reject(r.error);
        r.readAsDataURL(new Blob([bytes]));
      });
    return {
      header: await b64(header),
      frame: await b64(frame),
      frames: frames && (await Promise.all(frames.map(b64))),
      seq,
      readback: await b64(new Uint8Array(xyz.buffer, xyz.byteOffset, xyz.byteLength)),
    };
  });
}

/** Every frame of a synthetic stream decoded in order (deltas on the frames before). */
function decodeAll(s) {
  const d = new PaletteDecoder(s.model.bones, s.model.N);
  return s.frames.map((m) => {
    const r = d.decode(readMeshFrame(m).frame.data);
    return { rotations: r.rotations.slice(), translations: r.translations.slice(), xi: r.xi.slice() };
  });
}

function floats(buf) {
  const copy = Buffer.from(buf);
  return new Float32Array(copy.buffer, copy.byteOffset, copy.length / 4);
}

function diagonal([lo, hi]) {
  return Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

/** The row of CSR entry `e`. */
function rowOf(rowPtr, e) {
  let r = 0;
  while (rowPtr[r + 1] <= e) r++;
  return r;
}

/** The largest |a_i - b_i| and where. */
function maxError(a, b) {
  assert.equal(a.length, b.length, `lengths ${a.length} and ${b.length}`);
  let worst = 0;
  let at = -1;
  for (let i = 0; i < a.length; i++) {
    const e = Math.abs(a[i] - b[i]);
    if (!(e <= worst)) {
      worst = e;
      at = i;
      if (Number.isNaN(e)) break;
    }
  }
  return { worst, vertex: Math.floor(at / 3) };
}

// ---------------------------------------------------------------------------------------------

const watchdog = setTimeout(() => {
  console.error(`FAIL: the palette test did not finish within ${OVERALL_TIMEOUT_MS / 1000} s`);
  process.exit(1);
}, OVERALL_TIMEOUT_MS);

fs.mkdirSync(shots, { recursive: true });
const shotFiles = ["palette-vertices.png", "palette-palette.png", "palette-synthetic.png"];
for (const f of shotFiles) fs.rmSync(path.join(shots, f), { force: true });
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "crease-chromium-"));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath,
  headless: true,
  args: LAUNCH_ARGS,
  viewport: VIEWPORT,
});
console.log(`chromium ${context.browser()?.version() ?? "(version unknown)"} at ${executablePath}; server ${base}`);
await codecReady;

const pageErrors = [];
/** A new page, its errors collected (`expected`: console errors it is meant to cause). */
async function newPage(label, expected) {
  const page = await context.newPage();
  const errors = watchPage(page, label);
  page.on("close", () => pageErrors.push(...errors.filter((e) => !(expected && expected.test(e)))));
  return page;
}

/** The import map of the viewer's index.html, for pages that import its modules. */
const importMap = (await (await fetch(`${base}/`)).text()).match(/<script type="importmap">[\s\S]*?<\/script>/)?.[0];

try {
  await check("(a) palette frames decode as core::codec::palette does (codec.js PaletteDecoder)", async () => {
    let frames = 0;
    let worstQ = 0;
    let worstT = 0;
    for (const cfg of [
      { level: "base", bones: 40, frames: 20, keyframeInterval: 7 },
      { level: "detail", bones: 3, frames: 20, examples: 5 },
    ]) {
      const s = await syntheticStream({ ...cfg, K: 2 });
      const dec = new PaletteDecoder(cfg.bones, s.model.N);
      s.frames.forEach((msg, i) => {
        const d = dec.decode(readMeshFrame(msg).frame.data);
        assert.equal(d.seq, 100 + i, "seq");
        assert.equal(d.header.kind, i === 0 || (cfg.keyframeInterval && i % cfg.keyframeInterval === 0) ? 0 : 1, `frame ${i}: kind`);
        const exact = s.exact[i];
        exact.bones.forEach((b, k) => {
          const l = Math.hypot(...b.q);
          const q = b.q.map((x) => x / l);
          const got = Array.from(d.rotations.subarray(4 * k, 4 * k + 4));
          const e = Math.min(
            Math.hypot(...got.map((x, j) => x - q[j])),
            Math.hypot(...got.map((x, j) => x + q[j])),
          );
          worstQ = Math.max(worstQ, e);
          assert.ok(e <= ROTATION_ERROR + 1e-7, `frame ${i} bone ${k}: quaternion error ${e} > ${ROTATION_ERROR}`);
          for (let j = 0; j < 3; j++) {
            const te = Math.abs(d.translations[3 * k + j] - b.t[j]);
            worstT = Math.max(worstT, te / d.step[j]);
            assert.ok(te <= d.step[j] * 0.5 * 1.0001 + 1e-7, `frame ${i} bone ${k}: translation error ${te}`);
          }
        });
        exact.xi.forEach((x, j) => assert.ok(Object.is(d.xi[j], x), `xi ${j}: ${d.xi[j]}, sent ${x}`));
        frames++;
      });
    }
    // Malformed frames: each refused with an Error that says why.
    const bones = [0, 1, 2, 3].map((k) => ({ q: [0.1 * k, 0.5, -0.3, 0.8], t: [0.01 * k, 0.02, -0.01] }));
    const qbox = translationBox(0.06);
    const enc = new LaneEncoder(paletteLaneCount(4, 3), qbox);
    const key = enc.encode(3, paletteLanes(bones, [0.5, 1.0, -2], qbox), true);
    const delta = enc.encode(4, paletteLanes(bones.map((b) => ({ ...b, t: [0.03, 0.01, 0] })), [0.5, 1.5, -2], qbox), false);
    const fresh = () => new PaletteDecoder(4, 3);
    fresh().decode(key);
    const held = fresh();
    held.decode(key);
    held.decode(delta);
    const variant = (bytes, fn) => {
      const b = Uint8Array.from(bytes);
      fn(b, new DataView(b.buffer));
      return b;
    };
    const laneVariant = (fn) => {
      const l = paletteLanes(bones, [0.5, 1.0, -2], qbox);
      fn(l);
      return new LaneEncoder(paletteLaneCount(4, 3), qbox).encode(3, l, true);
    };
    const bad = {
      "10 bytes": [() => fresh(), key.subarray(0, 10), /shorter than the 52-byte header/],
      "one byte short": [() => fresh(), key.subarray(0, key.length - 1), /payload length/],
      magic: [() => fresh(), variant(key, (b) => (b[0] = 0x58)), /magic/],
      "version 2": [() => fresh(), variant(key, (b) => (b[4] = 2)), /version 2/],
      "another lane count": [() => new PaletteDecoder(5, 3), key, /lane vertices, expected 12 \(5 bones, 3 xi values\)/],
      "a delta and no frame held": [() => fresh(), delta, /no frame is held/],
      "a delta on another frame": [() => held, delta, /the frame held is 4/],
      "a delta in another box": [
        () => {
          const d = fresh();
          d.decode(key);
          return d;
        },
        variant(delta, (b, dv) => dv.setFloat32(36, 1e-3, true)),
        /another quantisation box/,
      ],
      "a corrupt payload": [() => fresh(), variant(key, (b) => b.fill(0xff, 53)), /palette frame 3/],
      "quaternion index 4": [() => fresh(), laneVariant((l) => (l[8 + 3] = 4)), /bone 1: quaternion index 4/],
      "NaN xi": [() => fresh(), laneVariant((l) => (l[4 * 8] = 0, l[4 * 8 + 1] = 0x7fc0)), /xi 0 is not finite/],
    };
    for (const [what, [decoder, b, re]] of Object.entries(bad)) {
      assert.throws(() => decoder().decode(b), (e) => e instanceof Error && re.test(e.message), `${what}: not refused as ${re}`);
    }
    // A refused codec frame leaves the decoder as it was: the next delta still applies.
    const d = fresh();
    d.decode(key);
    assert.throws(() => d.decode(variant(delta, (b) => b.fill(0xff, 53))));
    assert.equal(d.decode(delta).seq, 4, "the delta after a refused frame");
    // Every prefix and every single-byte change decodes or is refused with an Error.
    for (const frame of [key, delta]) {
      for (let cut = 0; cut < frame.length; cut++) {
        const dd = fresh();
        dd.decode(key);
        try {
          dd.decode(frame.subarray(0, cut));
        } catch (e) {
          assert.ok(e instanceof Error, `prefix ${cut}: threw ${e}`);
        }
      }
      for (let i = 0; i < frame.length; i++) {
        const dd = fresh();
        dd.decode(key);
        try {
          dd.decode(variant(frame, (b) => (b[i] ^= 0xa5)));
        } catch (e) {
          assert.ok(e instanceof Error, `byte ${i} changed: threw ${e}`);
        }
      }
    }
    return (
      `${frames} frames (keyframes and deltas) within the bounds (worst quaternion error ${worstQ.toExponential(2)} of ` +
      `${ROTATION_ERROR.toExponential(2)}, translation ${worstT.toFixed(3)} steps), ${Object.keys(bad).length} malformed ` +
      `frames refused, ${2 * (key.length + delta.length)} prefixes and byte changes without a crash`
    );
  });

  await check("(b) malformed palette headers are refused naming the field (palette.js)", async () => {
    // N = 4: three detail blocks (5 values per row, 2 per block).
    const s = await syntheticStream({ level: "detail", K: 3, bones: 4, steps: 2, examples: 4 });
    const t0 = readMeshFrame(s.header).paletteTopology;
    const h0 = decodePaletteTopology(t0);
    assert.equal(h0.levels, 2, "levels");
    assert.equal(t0.detailBlocks.length, 3, "detail blocks");
    const nb = s.baseVertices;
    const tris = s.model.baseTriangles;
    const fresh = () => readMeshFrame(Uint8Array.from(s.header)).paletteTopology;
    // The base triangles re-encoded (and their turns): `list` replaces them.
    const retriangle = (t, list) => {
      t.indices = baseIndices(list);
      t.triangleCount = list.length;
      t.triangleTurns = cornerTurns(t.indices, list);
    };
    const block = (j, fn) => (t) => {
      const b = Uint8Array.from(t.detailBlocks[j]);
      fn(b);
      t.detailBlocks[j] = b;
    };
    const cases = {
      "version 2": [(t) => (t.version = 2), /version 2/],
      "influences 9": [(t) => (t.influences = 9), /influences 9/],
      "skin weights short": [(t) => (t.skinWeights = t.skinWeights.subarray(2)), /skin weights has/],
      "a skin bone past the bones": [(t) => (t.bones = 1), /skin bone|skin bones/],
      "weights not summing to 65535": [(t) => (t.skinWeights = Uint8Array.from(t.skinWeights).fill(1, 0, 2)), /sum to/],
      "rest positions short": [(t) => (t.restPositions = t.restPositions.subarray(12)), /rest_positions/],
      "subdivision_levels 0": [(t) => (t.subdivisionLevels = 0), /palette header: subdivision_levels 0, expected 1..=3/],
      "subdivision_levels 4": [(t) => (t.subdivisionLevels = 4), /palette header: subdivision_levels 4, expected 1..=3/],
      "triangle_turns a byte short": [
        (t) => (t.triangleTurns = t.triangleTurns.subarray(1)),
        /palette header: triangle_turns is 1 bytes, expected 2 \(2 bits for each of 8 triangles\)/,
      ],
      "triangle_turns a byte long": [(t) => (t.triangleTurns = Uint8Array.from([...t.triangleTurns, 0])), /triangle_turns is 3 bytes, expected 2/],
      "a turn of 3": [(t) => (t.triangleTurns = Uint8Array.from(t.triangleTurns).fill(0xc0 | t.triangleTurns[1], 1, 2)), /triangle_turns: triangle 7 has turn 3/],
      "detail_step 0": [(t) => (t.detailStep = 0), /detail_step 0, expected a finite value > 0/],
      "detail_step NaN": [(t) => (t.detailStep = NaN), /detail_step NaN/],
      "a detail block missing": [(t) => t.detailBlocks.pop(), /detail_blocks has 2 blocks, expected 3 \(5 values per row, 2 per block\)/],
      "a detail block too many": [(t) => t.detailBlocks.push(t.detailBlocks[0]), /detail_blocks has 4 blocks, expected 3/],
      "a corrupt detail block": [block(1, (b) => b.fill(0xff, 1)), /palette header: detail_blocks\[1\]: /],
      "a detail block cut short": [(t) => (t.detailBlocks[2] = t.detailBlocks[2].subarray(0, t.detailBlocks[2].length - 3)), /palette header: detail_blocks\[2\]: /],
      "an empty detail block": [(t) => (t.detailBlocks[0] = new Uint8Array(0)), /detail_blocks\[0\] is empty/],
      "a detail block of meshopt version 0": [block(0, (b) => (b[0] = 0xa0)), /detail_blocks\[0\]: meshopt vertex codec byte 0xa0, expected 0xa1/],
      "vertex_count one more than the rebuild": [
        (t) => (t.vertexCount += 1),
        new RegExp(`palette header: vertex_count ${s.vertexCount + 1}, but 2 Loop levels of the base mesh give ${s.vertexCount}`),
      ],
      "vertex_count of one level fewer": [(t) => (t.subdivisionLevels = 1), /vertex_count \d+, but 1 Loop levels of the base mesh give 18/],
      "a triangle index past base_vertices": [
        (t) => retriangle(t, [...tris.slice(0, 7), [tris[7][0], tris[7][1], nb]]),
        new RegExp(`palette header: indices: triangle 7 has vertex ${nb}, only ${nb}`),
      ],
      "triangle_count past the indices' bytes": [(t) => (t.triangleCount = t.indices.length + 1), /triangle_count \d+, but indices has only \d+ bytes/],
      "indices corrupt": [(t) => (t.indices = Uint8Array.from(t.indices).fill(0xff, 1)), /palette header: indices: /],
      "a base triangle repeated (an edge in 3 triangles)": [
        (t) => retriangle(t, [...tris, tris[0]]),
        /palette header: the base triangles \(indices, triangle_turns\) do not subdivide: Loop subdivision: edge \(\d+, \d+\) is shared by 3 triangles/,
      ],
      "a degenerate base triangle": [
        (t) => retriangle(t, [...tris.slice(0, 7), [tris[7][0], tris[7][1], tris[7][0]]]),
        /do not subdivide: Loop subdivision: triangle 7 \[\d+, \d+, \d+\] is degenerate/,
      ],
      "two base triangles missing at one vertex (a bowtie)": [
        (t) => retriangle(t, tris.filter((_, i) => i !== 0 && i !== 2)),
        /do not subdivide: Loop subdivision: vertex 4 has 4 boundary edges/,
      ],
      "base level: vertex_count off": [(t) => ((t.level = 1), (t.vertexCount += 1)), /vertex_count 67, expected base_vertices 6 at the base level/],
    };
    for (const [what, [fn, re]] of Object.entries(cases)) {
      const t = fresh();
      fn(t);
      assert.throws(() => decodePaletteTopology(t), (e) => e instanceof Error && re.test(e.message), what);
    }
    // The base level ignores the detail fields; a base header decodes with the same arrays.
    const tb = fresh();
    tb.level = 1;
    tb.vertexCount = nb;
    const hb = decodePaletteTopology(tb);
    assert.equal(hb.steps.length, 0, "steps at the base level");
    assert.equal(hb.detail, null, "detail at the base level");
    return `${Object.keys(cases).length} malformed headers refused`;
  });

  await check("(b2) web/loop.js rebuilds every mesh of tests/vectors/loop-v1.json exactly (Node)", async () => {
    const v = JSON.parse(fs.readFileSync(loopVectorsPath, "utf8"));
    assert.equal(v.version, 1, "loop-v1.json version");
    assert.ok(v.meshes.length > 0, "loop-v1.json has no meshes");
    let entries = 0;
    let triangles = 0;
    const lines = [];
    for (const m of v.meshes) {
      const got = loopSteps(m.vertex_count, m.triangles.flat(), m.levels);
      assert.equal(got.steps.length, m.steps.length, `${m.name}: steps`);
      m.steps.forEach((w, l) => {
        const s = got.steps[l];
        const what = `${m.name}, step ${l}`;
        assert.equal(s.rows, w.rows, `${what}: rows`);
        assert.equal(s.columns, w.columns, `${what}: columns`);
        assert.deepEqual(Array.from(s.rowPtr), w.row_ptr, `${what}: row_ptr`);
        assert.deepEqual(Array.from(s.cols), w.cols, `${what}: cols`);
        assert.equal(s.weights.length, w.weights.length, `${what}: weights`);
        w.weights.forEach((x, e) => {
          const want = Math.fround(Number(x));
          assert.ok(Object.is(s.weights[e], want), `${what}: weight ${e} (row ${rowOf(w.row_ptr, e)}) is ${s.weights[e]}, expected ${x}`);
        });
        entries += w.weights.length;
      });
      assert.deepEqual(Array.from(got.triangles), m.subdivided_triangles.flat(), `${m.name}: subdivided triangles`);
      triangles += m.subdivided_triangles.length;
      lines.push(`${m.name} (L=${m.levels}, ${m.steps.at(-1).rows} vertices)`);
    }
    // And what it refuses, named as core names it.
    const refused = [
      [4, [0, 1, 2, 0, 2, 3], 0, /^Loop subdivision: 0 levels requested, expected 1..=3$/],
      [3, [0, 1, 2, 0, 2, 3], 1, /^Loop subdivision: triangle 1 refers to vertex 3, but there are only 3 vertices$/],
      [4, [0, 1, 2, 1, 1, 2], 1, /^Loop subdivision: triangle 1 \[1, 1, 2\] is degenerate \(repeats a vertex\)$/],
      [5, [0, 1, 2, 0, 1, 3, 1, 0, 4], 1, /^Loop subdivision: edge \(0, 1\) is shared by 3 triangles/],
      [5, [0, 1, 2, 0, 3, 4], 1, /^Loop subdivision: vertex 0 has 4 boundary edges/],
      // Two closed cones (tetrahedra) sharing their apex 0: two fans at vertex 0.
      [7, [0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2, 0, 4, 5, 0, 5, 6, 0, 6, 4, 4, 6, 5], 1, /^Loop subdivision: the triangles around vertex 0 form 2 separate fans/],
    ];
    for (const [n, t, levels, re] of refused) {
      assert.throws(() => loopSteps(n, t, levels), (e) => e instanceof Error && re.test(e.message), String(re));
    }
    return `${v.meshes.length} meshes (${lines.join(", ")}): ${entries} weights bit-exact, ${triangles} triangles; ${refused.length} bad meshes refused`;
  });

  assert.ok(importMap, "the viewer's index.html has no import map");
  const synthUrl = `${base}/__palette_synthetic.html`;
  const synthPage = await newPage("synthetic page");
  await synthPage.route(synthUrl, (r) =>
    r.fulfill({ contentType: "text/html", body: `<!doctype html><html><head>${importMap}</head><body></body></html>` }),
  );
  await synthPage.goto(synthUrl);

  await check("(c) GPU synthesis of synthetic streams matches an f64 reference", async () => {
    const configs = [
      // Bones over 256 (u16 skin bones), 8 influences, buffers 7 texels wide (many rows).
      { level: "base", K: 8, bones: 300, width: 7 },
      // Open and unchained fans, a vertex of no triangle (its normal zero).
      { level: "base", K: 2, bones: 4, width: 5, odd: true },
      // Two Loop steps, N = 5 (D rows over two texels).
      { level: "detail", K: 4, bones: 3, steps: 2, examples: 5, width: 7 },
      // One step, N + 1 = 4 (one texel), one influence, the default width.
      { level: "detail", K: 1, bones: 2, steps: 1, examples: 3, width: 0 },
      // A triangle missing: Loop's boundary rules, two levels, N + 1 = 3 (an odd last block).
      { level: "detail", K: 2, bones: 3, steps: 2, examples: 2, width: 5, open: true },
      // N = 300: xi in a texture rather than a uniform array.
      { level: "detail", K: 2, bones: 3, steps: 1, examples: 300, width: 64 },
    ];
    const lines = [];
    for (const cfg of configs) {
      const s = await syntheticStream({ ...cfg, frames: 3 });
      const tol = RELATIVE_TOLERANCE * diagonal(s.bounds);
      const got = await synthPage.evaluate(
        async ({ header, frames, width, bounds }) => {
          const THREE = await import("three");
          const { PaletteSynth } = await import("/palette.js");
          const { readMeshFrame } = await import("/wire.js");
          await (await import("/codec.js")).ready;
          const canvas = document.createElement("canvas");
          canvas.width = canvas.height = 96;
          const renderer = new THREE.WebGLRenderer({ canvas, preserveDrawingBuffer: true });
          const synth = new PaletteSynth(renderer, width ? { width } : {});
          synth.load(readMeshFrame(Uint8Array.from(header)).paletteTopology);
          const out = [];
          for (const f of frames) {
            synth.setFrame(readMeshFrame(Uint8Array.from(f)).frame.data);
            const ran = synth.update();
            out.push({ ran, again: synth.update(), pos: Array.from(synth.readback()), nrm: Array.from(synth.readback("normals")) });
          }
          // Drawn with the viewer's material: something lands on the canvas.
          const scene = new THREE.Scene();
          scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 2));
          const mesh = new THREE.Mesh(synth.geometry(), synth.material({ color: 0xd9a58c }));
          mesh.frustumCulled = false;
          scene.add(mesh);
          const c = new THREE.Vector3(...bounds[0]).add(new THREE.Vector3(...bounds[1])).multiplyScalar(0.5);
          const camera = new THREE.PerspectiveCamera(50, 1, 0.01, 10);
          camera.position.copy(c).add(new THREE.Vector3(0, 0, 0.6));
          camera.lookAt(c);
          renderer.setClearColor(0x000000, 1);
          renderer.render(scene, camera);
          const gl = renderer.getContext();
          const px = new Uint8Array(4 * 96 * 96);
          gl.readPixels(0, 0, 96, 96, gl.RGBA, gl.UNSIGNED_BYTE, px);
          let lit = 0;
          for (let i = 0; i < 96 * 96; i++) if (px[4 * i] + px[4 * i + 1] + px[4 * i + 2] > 30) lit++;
          synth.dispose();
          renderer.dispose();
          return { frames: out, lit };
        },
        { header: Array.from(s.header), frames: s.frames.map((f) => Array.from(f)), width: cfg.width, bounds: s.bounds },
      );
      got.frames.forEach((g, i) => {
        assert.ok(g.ran && !g.again, `frame ${i}: update() ran ${g.ran}, then again ${g.again}`);
        const ref = referenceMesh(s, decodeAll(s)[i]);
        const p = maxError(g.pos, ref.positions.flat());
        const n = maxError(g.nrm, ref.normals.flat());
        assert.ok(p.worst <= tol, `${cfg.level} frame ${i}: position error ${p.worst} at vertex ${p.vertex} > ${tol}`);
        assert.ok(n.worst <= NORMAL_TOLERANCE, `${cfg.level} frame ${i}: normal error ${n.worst} at vertex ${n.vertex}`);
        if (i === got.frames.length - 1) {
          lines.push(
            `${cfg.level}${cfg.odd ? " (odd fans)" : ""}${cfg.open ? " (open)" : ""} K=${cfg.K} B=${cfg.bones}${cfg.steps ? ` L=${cfg.steps} N=${cfg.examples}` : ""} ` +
              `W=${cfg.width || "default"}: ${s.vertexCount} vertices, position error ${p.worst.toExponential(2)} ` +
              `(${(p.worst / diagonal(s.bounds)).toExponential(1)} of the diagonal), normal ${n.worst.toExponential(1)}`,
          );
        }
      });
      assert.ok(got.lit > 20, `${cfg.level}: the drawn mesh lit ${got.lit} pixels of 96x96`);
    }
    figures.push(...lines.map((l) => `synthetic ${l}`));
    return lines.join("; ");
  });
  await check("(c2) palette test vectors (tests/vectors/palette-v1.json) decode and synthesise as core's in the page", async () => {
    const v = JSON.parse(fs.readFileSync(paletteVectorsPath, "utf8"));
    const headerBytes = Buffer.from(v.header_hex, "hex");
    // The rewriters are exact: the message re-encoded unchanged is its own bytes.
    assert.ok(withPaletteField(headerBytes, 23, (b) => b).equals(headerBytes), "re-encoding header_hex changes it");
    assert.ok(withPaletteVarint(headerBytes, 21, v.header.levels).equals(headerBytes), "re-encoding header_hex's levels changes it");
    const N = v.header.examples;
    const drawn = v.header.detail_rows.length / (N + 1);
    const levels = v.header.levels;
    const blocks = protoFields(protoFields(headerBytes).find((f) => f.field === 3).body).filter((f) => f.field === 23 && f.wire === 2);
    assert.equal(blocks.length, Math.ceil((N + 1) / 2), "detail_blocks in header_hex");
    blocks.forEach((b, j) => assert.equal(b.body[0], 0xa1, `detail_blocks[${j}]: meshopt's version byte`));
    const keyHex = v.frames[0].frame_hex;
    const deltaHex = v.frames[1].frame_hex;
    const variant = (bytes) => bytes.toString("hex");
    // Malformed variants: [what, header hex (null: the vector's), frames fed after it, the Error expected].
    const malformed = [
      ["the delta without its keyframe", null, [deltaHex], /palette frame 1: a delta on frame 0, and no frame is held/],
      ["the delta twice", null, [keyHex, deltaHex, deltaHex], /palette frame 1: a delta on frame 0, the frame held is 1/],
      ["the keyframe a byte short", null, [keyHex.slice(0, -2)], /frame: payload length \d+, but \d+ bytes follow the header/],
      ["the delta a byte short", null, [keyHex, deltaHex.slice(0, -2)], /frame: payload length/],
      [
        "detail_blocks[0] a byte short",
        variant(withPaletteField(headerBytes, 23, (b, k) => (k === 0 ? b.subarray(0, b.length - 1) : b))),
        [],
        /palette header: detail_blocks\[0\]: /,
      ],
      [
        "detail_blocks[1] corrupt",
        variant(withPaletteField(headerBytes, 23, (b, k) => (k === 1 ? Buffer.from(b).fill(0xff, 1) : b))),
        [],
        /palette header: detail_blocks\[1\]: /,
      ],
      [
        "a detail block missing",
        variant(withPaletteField(headerBytes, 23, (b, k) => (k === 0 ? null : b))),
        [],
        new RegExp(`palette header: detail_blocks has ${blocks.length - 1} blocks, expected ${blocks.length} \\(${N + 1} values per row, 2 per block\\)`),
      ],
      [
        "a detail block too many",
        variant(withPaletteField(headerBytes, 23, (b, k) => (k === 0 ? [b, b] : b))),
        [],
        new RegExp(`palette header: detail_blocks has ${blocks.length + 1} blocks, expected ${blocks.length}`),
      ],
      [
        "triangle_turns a byte short",
        variant(withPaletteField(headerBytes, 24, (b) => b.subarray(0, b.length - 1))),
        [],
        /palette header: triangle_turns is \d+ bytes, expected \d+/,
      ],
      [
        "a turn of 3 (triangle 0)",
        variant(withPaletteField(headerBytes, 24, (b) => Buffer.from([b[0] | 3, ...b.subarray(1)]))),
        [],
        /palette header: triangle_turns: triangle 0 has turn 3, expected 0, 1 or 2/,
      ],
      [
        "vertex_count one more than the rebuild",
        variant(withPaletteVarint(headerBytes, 4, drawn + 1)),
        [],
        new RegExp(`palette header: vertex_count ${drawn + 1}, but ${levels} Loop levels of the base mesh give ${drawn}`),
      ],
      ["subdivision_levels 0", variant(withPaletteVarint(headerBytes, 21, 0)), [], /palette header: subdivision_levels 0, expected 1..=3/],
      ["subdivision_levels 4", variant(withPaletteVarint(headerBytes, 21, 4)), [], /palette header: subdivision_levels 4, expected 1..=3/],
      ["header_hex cut 10 bytes short", v.header_hex.slice(0, -20), [], /protobuf: truncated field/],
    ];
    const r = await synthPage.evaluate(
      async ({ v, malformed }) => {
        const THREE = await import("three");
        const { PaletteSynth, decodePaletteTopology } = await import("/palette.js");
        const { readMeshFrame, littleEndian } = await import("/wire.js");
        const codec = await import("/codec.js");
        await codec.ready;
        const { MeshoptDecoder } = await import("/node_modules/meshoptimizer/meshopt_decoder.mjs");
        const bad = [];
        const counts = {};
        const count = (what, n = 1) => (counts[what] = (counts[what] || 0) + n);
        const hex = (s) => Uint8Array.from((s.match(/../g) || []).map((h) => parseInt(h, 16)));
        // Floats are strings (as codec-v1.json): the shortest decimal of an f32.
        const f32 = (s) => Math.fround(Number(s));
        // Bit-exact for f32 values: Object.is tells -0 from 0 and NaN equals NaN.
        const same = (a, e) => Object.is(Math.fround(a), typeof e === "string" ? f32(e) : Math.fround(e));
        const cmp = (kind, eq) => (what, got, want) => {
          const flat = want.flat(Infinity);
          if (!got || got.length !== flat.length) {
            bad.push(`${what}: length ${got && got.length}, expected ${flat.length}`);
            return;
          }
          for (let i = 0; i < flat.length; i++) {
            if (!eq(got[i], flat[i])) {
              bad.push(`${what}[${i}]: ${got[i]}, expected ${flat[i]}`);
              return;
            }
          }
          count(kind, flat.length);
        };
        const cmpFloats = cmp("floats", same);
        const cmpInts = cmp("integers", (a, e) => a === e);
        const cmpValue = (what, got, want) => (got === want ? count("integers") : bad.push(`${what}: ${got}, expected ${want}`));
        const want = v.header;

        // 1. The header: wire.js's reader, then palette.js's checks and arrays (what the viewer does).
        const t = readMeshFrame(hex(v.header_hex)).paletteTopology;
        if (!t) return { bad: ["header_hex: readMeshFrame gave no paletteTopology"] };
        cmpValue("model", t.model, "tetra");
        cmpValue("level", t.level, 2);
        cmpValue("version", t.version, v.version);
        let h;
        try {
          h = decodePaletteTopology(t);
        } catch (e) {
          return { bad: [`decodePaletteTopology: ${e.message}`] };
        }
        cmpValue("decoded level", h.level, "detail");
        cmpValue("bones", h.bones, want.bones);
        cmpValue("baseVertices", h.baseVertices, want.rest.length);
        cmpValue("influences", h.influences, want.influences);
        cmpValue("examples", h.examples, want.examples);
        const N = want.examples;
        const nv = want.detail_rows.length / (N + 1);
        cmpValue("vertexCount (drawn)", h.vertexCount, nv);
        cmpValue("triangle_count (base)", t.triangleCount, want.triangles.length);
        cmpValue("triangleCount (drawn)", h.triangleCount, want.drawn_triangles.length);
        cmpValue("subdivision_levels", t.subdivisionLevels, want.levels);
        cmpValue("levels", h.levels, want.levels);
        cmpFloats("bounds.min", h.bounds.min, ["-1.0", "-1.0", "-1.0"]);
        cmpFloats("bounds.max", h.bounds.max, ["2.0", "2.0", "2.0"]);
        cmpFloats("rest", h.rest, want.rest);
        cmpInts("skinBones", h.skinBones, want.skin_bones);
        // The 16-bit weights as sent, and as the JS exposes them (q / 65535 in f32).
        cmpInts("skin_weights (u16)", littleEndian(t.skinWeights, Uint16Array, "skin_weights"), want.skin_weights);
        cmpFloats("skinWeights", h.skinWeights, want.skin_weights.map((q) => Math.fround(q / 65535)));
        // The base triangles: as the index codec gives them back (it may rotate a triangle's
        // corners, winding kept), the turns sent, and turned back: the model's.
        const raw = codec.decodeIndices(t.indices, t.triangleCount, t.baseVertices);
        cmpInts("triangles (as decoded)", raw, want.decoded_triangles);
        cmpInts("triangle_turns", t.triangleTurns, want.triangle_turns);
        cmpInts("baseTriangles (turned back)", h.baseTriangles, want.triangles);
        let rotated = 0;
        want.triangles.forEach((w, i) => {
          if (w.some((x, k) => raw[3 * i + k] !== x)) rotated++;
        });
        // The Loop steps and the drawn triangles, rebuilt (loop.js) from the base triangles.
        cmpValue("steps", h.steps.length, want.steps.length);
        want.steps.forEach((ws, l) => {
          const s = h.steps[l];
          if (!s) return;
          cmpValue(`steps[${l}].rows`, s.rows, ws.row_ptr.length - 1);
          cmpValue(`steps[${l}].columns`, s.columns, ws.columns);
          cmpInts(`steps[${l}].rowPtr`, s.rowPtr, ws.row_ptr);
          cmpInts(`steps[${l}].cols`, s.cols, ws.cols);
          cmpFloats(`steps[${l}].weights`, s.weights, ws.weights);
        });
        cmpInts("triangles (drawn)", h.triangles, want.drawn_triangles);
        // D and b: the i16 q of the blocks (meshopt's decoder on its own), and as the JS
        // exposes them (f32(q * step)).
        cmpFloats("detail_step", [t.detailStep], [want.detail_step]);
        cmpFloats("detailStep", [h.detailStep], [want.detail_step]);
        const q = new Int16Array(nv * (N + 1));
        t.detailBlocks.forEach((data, j) => {
          const bytes = new Uint8Array(4 * nv);
          MeshoptDecoder.decodeVertexBuffer(bytes, nv, 4, data);
          const pair = new Int16Array(bytes.buffer);
          for (let v = 0; v < nv; v++) {
            q[v * (N + 1) + 2 * j] = pair[2 * v];
            if (2 * j + 1 <= N) q[v * (N + 1) + 2 * j + 1] = pair[2 * v + 1];
          }
        });
        cmpInts("detail_rows (i16, from detail_blocks)", q, want.detail_rows);
        cmpFloats("detail (q * step)", h.detail, want.detail_rows.map((x) => Math.fround(x * f32(want.detail_step))));

        // 2. The frames in order: PaletteDecoder (the viewer's, through PaletteSynth), and
        // decodeFrame + readPaletteLanes on their own.
        const dec = new codec.PaletteDecoder(h.bones, h.examples);
        let prev = null;
        const cmpFrame = (what, d, f) => {
          cmpFloats(`${what} rotations`, d.rotations, f.decoded_bones.map((b) => b.rotation_xyzw));
          cmpFloats(`${what} translations`, d.translations, f.decoded_bones.map((b) => b.translation));
          cmpFloats(`${what} xi`, d.xi, f.decoded_xi);
        };
        v.frames.forEach((f, i) => {
          const what = `frame ${i} (${f.kind})`;
          try {
            const d = dec.decode(hex(f.frame_hex));
            cmpValue(`${what} kind`, d.header.kind, f.kind === "Key" ? 0 : 1);
            cmpValue(`${what} seq`, d.seq, i);
            cmpInts(`${what} lanes (PaletteDecoder)`, dec.lanes, f.lanes);
            cmpFrame(`${what} PaletteDecoder`, d, f);
            const r = codec.decodeFrame(hex(f.frame_hex), prev);
            cmpInts(`${what} lanes (decodeFrame)`, r.lanes, f.lanes);
            cmpFrame(`${what} readPaletteLanes`, codec.readPaletteLanes(r.lanes, r.positions, h.bones, h.examples), f);
            prev = r.lanes;
            count("frames");
          } catch (e) {
            bad.push(`${what}: threw ${e.message}`);
          }
        });

        // 3. The GPU synthesis (the viewer's PaletteSynth), at the default buffer width and 3
        // texels wide (every buffer over several rows).
        const canvas = document.createElement("canvas");
        canvas.width = canvas.height = 16;
        const renderer = new THREE.WebGLRenderer({ canvas });
        const gpu = {};
        for (const width of [0, 3]) {
          const synth = new PaletteSynth(renderer, width ? { width } : {});
          synth.load(readMeshFrame(hex(v.header_hex)).paletteTopology);
          gpu[width ? `${width} texels wide` : "default width"] = v.frames.map((f, i) => {
            const d = synth.setFrame(hex(f.frame_hex));
            cmpFrame(`W=${width} frame ${i} setFrame`, d, f);
            const ran = synth.update();
            return { ran, positions: Array.from(synth.readback()) };
          });
          synth.dispose();
        }

        // 4. Malformed variants: each an Error with a message, through the decoder and the
        // synthesiser alike; a refused one leaves the synthesiser able to take the stream again.
        const refusals = [];
        const synth = new PaletteSynth(renderer);
        for (const [what, headerHex, frames] of malformed) {
          const tried = [];
          for (const via of ["PaletteDecoder", "PaletteSynth"]) {
            let error = null;
            try {
              const top = readMeshFrame(hex(headerHex || v.header_hex)).paletteTopology;
              if (via === "PaletteSynth") {
                synth.load(top);
                for (const f of frames) synth.setFrame(hex(f));
              } else {
                const hh = decodePaletteTopology(top);
                const d = new codec.PaletteDecoder(hh.bones, hh.examples);
                for (const f of frames) d.decode(hex(f));
              }
            } catch (e) {
              error = { isError: e instanceof Error, message: String(e && e.message) };
            }
            tried.push({ via, error });
          }
          refusals.push({ what, tried });
        }
        synth.load(readMeshFrame(hex(v.header_hex)).paletteTopology);
        const after = v.frames.map((f) => {
          synth.setFrame(hex(f.frame_hex));
          synth.update();
          return Array.from(synth.readback());
        });
        synth.dispose();
        renderer.dispose();
        return { bad, counts, rotated, gpu, refusals, after };
      },
      { v, malformed: malformed.map(([what, header, frames]) => [what, header, frames]) },
    );
    assert.deepEqual(r.bad, [], `mismatches:\n    ${r.bad.join("\n    ")}`);
    const diag = diagonal([[-1, -1, -1], [2, 2, 2]]);
    const tol = RELATIVE_TOLERANCE * diag;
    const errs = [];
    for (const [width, frames] of Object.entries(r.gpu)) {
      frames.forEach((g, i) => {
        assert.ok(g.ran, `${width}, frame ${i}: update() did not run`);
        const e = maxError(g.positions, v.frames[i].synthesized.flat().map((x) => Math.fround(Number(x))));
        errs.push(e.worst);
        figures.push(
          `palette-v1.json, ${width}, frame ${i} (${v.frames[i].kind}): max |gpu - core| ${e.worst.toExponential(3)} ` +
            `(${(e.worst / diag).toExponential(2)} of the bounds' diagonal ${diag.toFixed(4)}; allowed ${tol.toExponential(2)}) at vertex ${e.vertex}`,
        );
        assert.ok(e.worst <= tol, `${width}, frame ${i}: max |gpu - core| ${e.worst} at vertex ${e.vertex} > ${tol}`);
      });
    }
    r.after.forEach((p, i) => {
      const e = maxError(p, r.gpu["default width"][i].positions);
      assert.equal(e.worst, 0, `frame ${i} after the refusals: differs from before by ${e.worst} at vertex ${e.vertex}`);
    });
    for (const { what, tried } of r.refusals) {
      const re = malformed.find((m) => m[0] === what)[3];
      for (const { via, error } of tried) {
        assert.ok(error, `${what} (${via}): not refused`);
        assert.ok(error.isError, `${what} (${via}): threw a non-Error ${error.message}`);
        assert.match(error.message, re, `${what} (${via})`);
      }
    }
    if (r.rotated) {
      notes.push(
        `palette-v1.json: ${r.rotated} of ${v.header.triangles.length} triangles decode with their corners rotated ` +
          `(winding kept), as decoded_triangles has them`,
      );
    }
    return (
      `header: ${r.counts.integers} integers and ${r.counts.floats} floats bit-exact (base triangles, ${r.rotated} of ` +
      `${v.header.triangles.length} rotated by the index codec and turned back; the rebuilt Loop steps and drawn triangles; ` +
      `D and b); ${r.counts.frames} frames' lanes, bones and xi bit-exact; GPU vs core max ` +
      `${Math.max(...errs).toExponential(2)} (allowed ${tol.toExponential(2)}); ${malformed.length} malformed variants ` +
      `refused by PaletteDecoder and PaletteSynth`
    );
  });
  await synthPage.close();

  await check("(d) the viewer on a mocked palette socket: overlay, window.crease.palette, bad frames, reconnects", async () => {
    // A room the test makes up: its /api document, and a socket that streams a synthetic
    // palette (base level first, the detail level on the second connection: a rebuild with
    // other sizes), closing the first connection itself (as a server going away does).
    const s1 = await syntheticStream({ level: "base", K: 4, bones: 5, frames: 3, seed: 1 });
    const s2 = await syntheticStream({ level: "detail", K: 2, bones: 5, frames: 3, seed: 2 });
    const page = await newPage("mocked page", /palette frame|WebSocket/);
    const doc = {
      base_vertices: s1.baseVertices,
      beta: 3,
      bounds: s1.bounds,
      control_points: [{ id: 0, name: "tip", rest: [0.1, 0.08, 0], vertex: 0 }],
      detail_vertices: s2.vertexCount,
      has_detail: true,
      model: "synthetic",
      room: "synthetic",
    };
    await page.route(`${base}/api/rooms/synthetic`, (r) => r.fulfill({ json: doc }));
    await page.route(`${base}/api/rooms`, (r) => r.fulfill({ json: { rooms: ["synthetic"] } }));
    const sockets = [];
    await page.routeWebSocket(/\/ws\/rooms\/synthetic/, (ws) => {
      const k = sockets.length;
      const s = k === 0 ? s1 : s2;
      const entry = { url: ws.url(), sent: 0, timer: null, closed: false };
      sockets.push(entry);
      ws.onClose(() => {
        entry.closed = true;
        clearInterval(entry.timer);
      });
      ws.send(Buffer.from(s.header));
      let i = 0;
      entry.timer = setInterval(() => {
        if (entry.closed) return;
        ws.send(Buffer.from(s.frames[i++ % s.frames.length]));
        entry.sent++;
      }, 50);
      entry.ws = ws;
    });
    await page.goto(`${base}/?room=synthetic`, { waitUntil: "load" });
    const first = await waitForCrease(page, "palette frames", (c) => c.rendered > 2 && c.frames > 3, 20_000);
    assert.equal(first.encoding, "palette", "window.crease.encoding");
    assert.equal(first.paletteReason, "GPU", "window.crease.paletteReason");
    assert.equal(first.vertexCount, s1.vertexCount, "vertexCount");
    assert.equal(first.model, "synthetic", "model");
    assert.equal(first.error, null, "error");
    const url = new URL(sockets[0].url);
    assert.equal(url.searchParams.get("encoding"), "palette", `socket URL ${sockets[0].url}`);
    assert.equal(url.searchParams.get("level"), "base", `socket URL ${sockets[0].url}`);
    const text = await overlay(page);
    assert.match(text, /palette \(GPU\)/, `overlay: ${JSON.stringify(text)}`);
    assert.match(text, /frames\/s drawn/, `overlay: ${JSON.stringify(text)}`);
    // What the page shows is the frame it says, exactly the header and frame bytes sent.
    const compare = async (s, what) => {
      const c = await paletteCapture(page);
      assert.ok(c, `${what}: no window.crease.palette.frame`);
      assert.ok(Buffer.from(c.header, "base64").equals(Buffer.from(s.header)), `${what}: palette.header is not the header sent`);
      const frame = Buffer.from(c.frame, "base64");
      const i = s.frames.findIndex((f) => Buffer.from(f).equals(frame));
      assert.ok(i >= 0, `${what}: palette.frame is none of the frames sent`);
      // palette.frames: the keyframe (frame 0 of the cycle) up to this frame.
      assert.ok(c.frames && c.frames.length === i + 1, `${what}: palette.frames has ${c.frames && c.frames.length}, expected ${i + 1}`);
      c.frames.forEach((b, k) =>
        assert.ok(Buffer.from(b, "base64").equals(Buffer.from(s.frames[k])), `${what}: palette.frames[${k}]`),
      );
      assert.equal(c.seq, 100 + i, `${what}: palette.seq`);
      const e = maxError(floats(Buffer.from(c.readback, "base64")), referenceMesh(s, decodeAll(s)[i]).positions.flat());
      const tol = RELATIVE_TOLERANCE * diagonal(s.bounds);
      assert.ok(e.worst <= tol, `${what}: readback error ${e.worst} > ${tol}`);
      return e.worst;
    };
    const e1 = await compare(s1, "base");
    // The handle of the control point sits on skinned vertex 0.
    const handles = await page.evaluate(() => window.crease.handles.length);
    assert.equal(handles, 1, "handles");
    // A malformed frame: an error on the banner, the page goes on with the next good frames.
    // MeshFrame { frame { seq: 7, data: a palette frame 5 bytes short } }.
    const data = readMeshFrame(s1.frames[1]).frame.data;
    const short = data.subarray(0, data.length - 5);
    const frameMsg = Buffer.concat([Buffer.from([0x08, 7, 0x22]), varint(short.length), Buffer.from(short)]);
    const mesh = Buffer.concat([Buffer.from([0x12]), varint(frameMsg.length), frameMsg]);
    const before = await creaseState(page);
    sockets[0].ws.send(mesh);
    const errored = await waitForCrease(page, "the bad frame's error", (c) => c.error !== null, 5_000);
    assert.match(errored.error, /^frame 7: frame: payload length/, "window.crease.error");
    const banner = await page.evaluate(() => [document.getElementById("banner").className, document.getElementById("banner").textContent]);
    assert.equal(banner[0], "error", `banner ${JSON.stringify(banner)}`);
    await waitForCrease(page, "frames after the bad one", (c) => c.rendered > before.rendered + 3, 10_000);
    // The server closes the socket: the viewer reconnects, gets the (detail) header, rebuilds.
    sockets[0].ws.close({ code: 1011, reason: "test: server going away" });
    const second = await waitForCrease(
      page,
      "the header again after the server closed the socket",
      (c) => c.headers === 2 && c.vertexCount === s2.vertexCount && c.rendered > before.rendered + 6,
      20_000,
    );
    assert.equal(sockets.length, 2, "sockets opened");
    assert.equal(second.sockets, 2, "window.crease.sockets");
    const e2 = await compare(s2, "after the reconnect (detail)");
    const img = decodePng(await screenshotPng(page).then((png) => (fs.writeFileSync(path.join(shots, "palette-synthetic.png"), png), png)));
    const fg = imageStats(img).foreground;
    assert.ok(fg > 0.005, `the synthetic mesh is not on the canvas (${(100 * fg).toFixed(2)}% foreground)`);
    // The page's own reconnect: a third socket, the header again.
    await page.evaluate(() => window.crease.reconnect());
    const third = await waitForCrease(page, "the header after reconnect()", (c) => c.headers === 3 && c.frames > second.frames + 3, 20_000);
    assert.equal(third.error, null, "reconnect() clears the error");
    await compare(s2, "after reconnect()");
    for (const s of sockets) s.ws.close();
    await page.close();
    return (
      `readback error ${e1.toExponential(2)} (base), ${e2.toExponential(2)} (detail after a reconnect); ` +
      `bad frame refused ("${errored.error}"); ${sockets.length} sockets, 3 headers`
    );
  });

  await check("(e) no float render targets: encoding=auto falls back to vertices and says why", async () => {
    const page = await newPage("fallback page");
    await page.addInitScript(() => {
      for (const C of [WebGL2RenderingContext, WebGLRenderingContext]) {
        const get = C.prototype.getExtension;
        C.prototype.getExtension = function (name) {
          return /^EXT_color_buffer_(half_)?float$/.test(name) ? null : get.call(this, name);
        };
        const list = C.prototype.getSupportedExtensions;
        C.prototype.getSupportedExtensions = function () {
          return (list.call(this) || []).filter((n) => !/^EXT_color_buffer_(half_)?float$/.test(n));
        };
      }
    });
    const urls = [];
    page.on("websocket", (ws) => urls.push(ws.url()));
    await page.goto(`${base}/?room=demo&encoding=auto`, { waitUntil: "load" });
    const c = await waitForCrease(page, "frames", (c) => c.frames > 3 && c.rendered > 0, 30_000);
    assert.equal(c.encoding, "vertices", "window.crease.encoding");
    assert.equal(c.paletteReason, "no float render targets", "window.crease.paletteReason");
    assert.equal(c.error, null, "error");
    assert.equal(await page.evaluate(() => window.crease.palette), null, "window.crease.palette");
    assert.ok(urls.length && new URL(urls[0]).searchParams.get("encoding") === "vertices", `socket URLs ${urls}`);
    const text = await overlay(page);
    assert.match(text, /vertices \(no float render targets\)/, `overlay ${JSON.stringify(text)}`);
    await page.close();
    return `overlay "${text.split("\n")[1]}", socket ${new URL(urls[0]).search}`;
  });

  if (syntheticOnly) {
    notes.push("PALETTE_ONLY=synthetic: the checks against the palette server were skipped");
  } else {
    await serverChecks();
  }
} catch (e) {
  fail();
  results.push(`FAIL ${e && e.stack ? e.stack : e}`);
  console.log(results.at(-1));
} finally {
  for (const p of context.pages()) await p.close().catch(() => {});
  await context.close().catch(() => {});
  fs.rmSync(userDataDir, { recursive: true, force: true });
  clearTimeout(watchdog);
}

function varint(v) {
  const out = [];
  do {
    let b = v & 0x7f;
    v = Math.floor(v / 128);
    if (v > 0) b |= 0x80;
    out.push(b);
  } while (v > 0);
  return Buffer.from(out);
}

/** The fields of a protobuf message, in order: {field, wire, raw (key and value bytes), body
 * (a length-delimited field's bytes)}. */
function protoFields(bytes) {
  const out = [];
  let pos = 0;
  const read = () => {
    let v = 0;
    let scale = 1;
    let b;
    do {
      b = bytes[pos++];
      v += (b & 0x7f) * scale;
      scale *= 128;
    } while (b & 0x80);
    return v;
  };
  while (pos < bytes.length) {
    const start = pos;
    const key = read();
    const wire = key & 7;
    let body = null;
    if (wire === 0) read();
    else if (wire === 1) pos += 8;
    else if (wire === 5) pos += 4;
    else if (wire === 2) {
      const len = read();
      body = bytes.subarray(pos, pos + len);
      pos += len;
    } else throw new Error(`protobuf: wire type ${wire}`);
    out.push({ field: Math.floor(key / 8), wire, raw: bytes.subarray(start, pos), body });
  }
  return out;
}

/** A length-delimited field, key and length in front. */
function lengthDelimited(field, body) {
  return Buffer.concat([varint(field * 8 + 2), varint(body.length), Buffer.from(body)]);
}

/** A MeshFrame of a PaletteTopology (field 3) with each occurrence k of the topology's
 * length-delimited field `field` replaced by fn(its bytes, k): bytes, an array of them (the
 * field repeated), or null (dropped); re-encoded (the lengths around it follow). */
function withPaletteField(meshFrame, field, fn) {
  return withPaletteTopology(meshFrame, (fields) => {
    let k = 0;
    return fields.flatMap((g) => {
      if (!(g.field === field && g.wire === 2)) return [Buffer.from(g.raw)];
      const out = fn(g.body, k++);
      return out === null ? [] : (Array.isArray(out) ? out : [out]).map((b) => lengthDelimited(field, b));
    });
  });
}

/** A MeshFrame of a PaletteTopology with its varint field `field` set to `value` (added at the
 * end when absent). */
function withPaletteVarint(meshFrame, field, value) {
  return withPaletteTopology(meshFrame, (fields) => {
    const encoded = Buffer.concat([varint(field * 8), varint(value)]);
    const out = fields.map((g) => (g.field === field && g.wire === 0 ? encoded : Buffer.from(g.raw)));
    if (!fields.some((g) => g.field === field && g.wire === 0)) out.push(encoded);
    return out;
  });
}

/** A MeshFrame whose PaletteTopology (field 3) is rewritten by fn(its fields) -> Buffers. */
function withPaletteTopology(meshFrame, fn) {
  return Buffer.concat(
    protoFields(meshFrame).map((f) =>
      f.field === 3 && f.wire === 2 ? lengthDelimited(3, Buffer.concat(fn(protoFields(f.body)))) : Buffer.from(f.raw),
    ),
  );
}

// ---------------------------------------------------------------------------------------------
// Against the live server's demo room.

async function serverChecks() {
  const roomInfo = await (await fetch(`${base}/api/rooms/demo`)).json();
  const diag = diagonal(roomInfo.bounds);

  /** A viewer page on the demo room, waited on until it draws frames. */
  async function viewer(query, label, minFrames = 2) {
    const page = await newPage(label);
    await page.goto(`${base}/?room=demo&${query}`, { waitUntil: "load" });
    const c = await waitForCrease(page, `${label}: frames`, (c) => c.rendered >= minFrames && c.frames >= minFrames, 120_000);
    return { page, state: c };
  }

  for (const level of ["detail", "base"]) {
    await check(`(f) ${level} level: the GPU's mesh is the Rust core's (crease decode-stream)`, async () => {
      assert.ok(fs.existsSync(creaseBin), `no ${creaseBin} (set CREASE_BIN)`);
      const { page, state } = await viewer(`level=${level}&encoding=palette`, `${level} palette page`);
      assert.equal(state.encoding, "palette", `window.crease.encoding (reason: ${state.paletteReason})`);
      const c = await paletteCapture(page);
      // Issue 41: the header's decoding in this page, the Loop rebuild on its own (both run
      // again here, warm: the viewer's own first run is in headerLoadMs).
      const rebuild =
        level === "detail" && c
          ? await page.evaluate(async () => {
              const { readMeshFrame } = await import("/wire.js");
              const { decodePaletteTopology } = await import("/palette.js");
              const { loopSteps } = await import("/loop.js");
              const t = readMeshFrame(window.crease.palette.header).paletteTopology;
              const t0 = performance.now();
              const h = decodePaletteTopology(t);
              const t1 = performance.now();
              loopSteps(h.baseVertices, h.baseTriangles, h.levels);
              const t2 = performance.now();
              return {
                decodeMs: t1 - t0,
                loopMs: t2 - t1,
                baseVertices: h.baseVertices,
                baseTriangles: h.baseTriangles.length / 3,
                levels: h.levels,
                vertices: h.vertexCount,
                triangles: h.triangleCount,
                examples: h.examples,
              };
            })
          : null;
      await page.close();
      assert.ok(c, "no window.crease.palette.frame");
      const header = Buffer.from(c.header, "base64");
      const frame = Buffer.from(c.frame, "base64");
      // The frames from the last keyframe to the displayed one (deltas need their bases).
      assert.ok(c.frames && c.frames.length > 0, "no window.crease.palette.frames");
      const frames = c.frames.map((b) => Buffer.from(b, "base64"));
      assert.ok(frames.at(-1).equals(frame), "palette.frames does not end with palette.frame");
      const gpu = floats(Buffer.from(c.readback, "base64"));
      const dir = fs.mkdtempSync(path.join(os.tmpdir(), "crease-palette-"));
      try {
        const capture = path.join(dir, `${level}.capture`);
        const len = (b) => {
          const l = Buffer.alloc(4);
          l.writeUInt32LE(b.length);
          return l;
        };
        fs.writeFileSync(capture, Buffer.concat([len(header), header, ...frames.flatMap((m) => [len(m), m])]));
        // Kept for a person: the capture and what the GPU made of it.
        fs.copyFileSync(capture, path.join(shots, `palette-${level}.capture`));
        fs.writeFileSync(path.join(shots, `palette-${level}.gpu.f32`), Buffer.from(gpu.buffer, gpu.byteOffset, gpu.byteLength));
        const out = path.join(dir, `${level}.f32`);
        const stdout = execFileSync(creaseBin, ["decode-stream", capture, "--out", out], { encoding: "utf8", timeout: 120_000 });
        const line = stdout.trim().split("\n").filter((l) => l.startsWith("{")).at(-1);
        assert.ok(line, `decode-stream printed no JSON line: ${stdout}`);
        const info = JSON.parse(line);
        assert.equal(info.encoding, "palette", `decode-stream: ${line}`);
        assert.equal(info.level, level, `decode-stream: ${line}`);
        assert.equal(info.frames, frames.length, `decode-stream: ${line}`);
        assert.equal(info.seq, c.seq, `decode-stream seq vs window.crease.palette.seq: ${line}`);
        assert.equal(info.vertex_count * 3, gpu.length, `decode-stream vertex_count vs the readback: ${line}`);
        const core = floats(fs.readFileSync(out));
        const e = maxError(gpu, core);
        const tol = RELATIVE_TOLERANCE * diag;
        // The largest differences sit where a vertex's normal sum nearly cancels (|sum| ~1e-8
        // where most are ~2e-6: f32 rounding of the edges decides its direction, on both
        // sides) and |h| is large; how many vertices come within a tenth of the bound.
        let near = 0;
        for (let i = 0; i < gpu.length; i += 3) {
          const d = Math.max(Math.abs(gpu[i] - core[i]), Math.abs(gpu[i + 1] - core[i + 1]), Math.abs(gpu[i + 2] - core[i + 2]));
          if (d > tol / 10) near++;
        }
        figures.push(
          `${level}: max |gpu - core| ${e.worst.toExponential(3)} m (${(e.worst / diag).toExponential(2)} of the ` +
            `bounds' diagonal ${diag.toFixed(4)} m; allowed ${tol.toExponential(2)}) at vertex ${e.vertex}, ` +
            `${near} vertices over a tenth of that; ${info.vertex_count} vertices, seq ${c.seq}, ${frames.length} frames from the keyframe`,
        );
        assert.ok(
          e.worst <= tol,
          `max |gpu - core| ${e.worst} at vertex ${e.vertex} > ${tol} (${near} vertices over ${tol / 10}; the capture and ` +
            `the GPU's positions are kept in ${shots} as palette-${level}.capture and palette-${level}.gpu.f32)`,
        );
        // The header reached the page in a bounded time (loopback; the GPU set-up after it not
        // counted).
        assert.ok(
          Number.isFinite(state.headerMs) && state.headerMs <= HEADER_LIMIT_MS,
          `the ${level} header took ${state.headerMs} ms (limit ${HEADER_LIMIT_MS})`,
        );
        assert.equal(state.headerBytes, header.length, "window.crease.headerBytes");
        // Issue 41 asks for the first detail frame drawn within 1 s of subscribing, on
        // loopback: printed, never asserted (a loaded machine is slower).
        figures.push(
          `${level}: the palette header, ${header.length} B, read ${state.headerMs} ms after the socket opened (the ` +
            `subscribe request), decoded and set up in ${state.headerLoadMs} ms; the first frame drawn ` +
            `${state.firstFrameMs} ms after the socket opened${level === "detail" ? " (issue 41: <= 1000 ms on loopback)" : ""}`,
        );
        if (rebuild) {
          figures.push(
            `${level}: the header decoded again in the page in ${rebuild.decodeMs.toFixed(1)} ms; loop.js alone, rebuilding ` +
              `${rebuild.levels} Loop levels (${rebuild.baseVertices} base vertices, ${rebuild.baseTriangles} triangles -> ` +
              `${rebuild.vertices} vertices, ${rebuild.triangles} triangles) ${rebuild.loopMs.toFixed(1)} ms; N = ${rebuild.examples}`,
          );
        }
        return (
          `${info.vertex_count} vertices, max |gpu - core| ${e.worst.toExponential(3)} (${(e.worst / diag).toExponential(2)} ` +
          `of the diagonal), header ${header.length} B in ${state.headerMs} ms, first frame drawn at ${state.firstFrameMs} ms, ` +
          `${frames.length} frames (${frame.length} B the last)`
        );
      } finally {
        fs.rmSync(dir, { recursive: true, force: true });
      }
    });
  }

  await check("(g) reconnects on the live server: the header again, after a close by the server side and after reconnect()", async () => {
    const page = await newPage("reconnect page", /WebSocket/);
    let routes = 0;
    let firstRoute = null;
    // A proxy to the real server; closing its page side is, to the page, the server closing.
    await page.routeWebSocket(/\/ws\/rooms\/demo/, (ws) => {
      routes++;
      ws.connectToServer();
      if (!firstRoute) firstRoute = ws;
    });
    await page.goto(`${base}/?room=demo&encoding=palette`, { waitUntil: "load" });
    const a = await waitForCrease(page, "frames", (c) => c.headers === 1 && c.rendered > 2, 60_000);
    assert.equal(a.encoding, "palette", "encoding");
    firstRoute.close({ code: 1001, reason: "test: going away" });
    const b = await waitForCrease(page, "the header after the close", (c) => c.headers === 2 && c.frames > a.frames + 3 && c.connected, 30_000);
    await page.evaluate(() => window.crease.reconnect());
    const c = await waitForCrease(page, "the header after reconnect()", (c) => c.headers === 3 && c.frames > b.frames + 3, 30_000);
    assert.equal(c.error, null, "error");
    assert.equal(routes, 3, "sockets the page opened");
    const cap = await paletteCapture(page);
    assert.ok(cap && cap.header.length > 0, "window.crease.palette after the reconnects");
    await page.close();
    return `3 sockets, 3 headers, ${c.frames} frames, encoding ${c.encoding}`;
  });

  // A fixed pose (the control points' rest positions), published over and over: the demo
  // animation yields to another publisher (demo/src/animation.rs: it pauses until none came
  // for 3 s), so every frame is the same pose and both encodings show the same mesh.
  const publisher = await newPage("publisher page");
  await publisher.goto(`${base}/healthz`);
  const positions = roomInfo.control_points.flatMap((c) => c.rest);
  await publisher.evaluate(
    ({ url, positions, token }) => {
      window.pub = { acks: 0, superseded: 0, errors: [], seq: 0 };
      // The token in the subprotocols (server/src/ws.rs): base64url of its UTF-8 bytes.
      const b64 = btoa(String.fromCharCode(...new TextEncoder().encode(token)))
        .replace(/\+/g, "-")
        .replace(/\//g, "_")
        .replace(/=+$/, "");
      const ws = new WebSocket(url, ["crease.v1", `crease.token.${b64}`]);
      window.pub.ws = ws;
      ws.onmessage = (e) => {
        const ack = JSON.parse(e.data);
        window.pub.acks++;
        // Code 10 (ABORTED): a newer frame of ours reached the room while this one waited
        // (latest wins, server/src/mailbox.rs); on a busy machine a detail frame can take
        // longer than the 100 ms between sends. The room is at the same pose either way.
        if (ack.error && ack.error.code === 10) window.pub.superseded++;
        else if (ack.error) window.pub.errors.push(ack.error.message);
      };
      ws.onopen = () => {
        window.pub.timer = setInterval(() => {
          ws.send(JSON.stringify({ seq: window.pub.seq++, capture_time_us: Date.now() * 1000, positions }));
        }, 100);
      };
    },
    { url: `ws://${httpAddr}/ws/rooms/demo?subscribe=false`, positions, token },
  );
  const stopPublishing = () =>
    publisher.evaluate(() => {
      clearInterval(window.pub.timer);
      window.pub.ws.close();
      return window.pub;
    });

  await check("(h) screenshots: the same frame in both encodings (detail level, fixed pose)", async () => {
    const deadline = Date.now() + 10_000;
    let pub;
    while (Date.now() < deadline) {
      pub = await publisher.evaluate(() => ({
        acks: window.pub.acks,
        superseded: window.pub.superseded,
        errors: window.pub.errors,
      }));
      if (pub.acks - pub.superseded >= 5 || pub.errors.length > 0) break;
      await sleep(100);
    }
    assert.ok(
      pub.acks - pub.superseded >= 5 && pub.errors.length === 0,
      `publishing the fixed pose: 5 frames taken and none refused but as superseded: ${JSON.stringify(pub)}`,
    );
    const imgs = {};
    for (const encoding of ["vertices", "palette"]) {
      const { page, state } = await viewer(`level=detail&encoding=${encoding}`, `${encoding} screenshot page`, 3);
      assert.equal(state.encoding, encoding, "window.crease.encoding");
      // Two more frames (the pose held), then the canvas alone.
      await waitForCrease(page, "two more frames", (c) => c.rendered >= state.rendered + 2, 60_000);
      await page.addStyleTag({ content: "#panel, #help, #banner { display: none !important; }" });
      await sleep(500);
      // The canvas fills the viewport; a fixed clip spares a round trip into the busy page.
      const png = await capturePng(page, { x: 0, y: 0, ...VIEWPORT }).catch((e) => {
        throw new Error(`${encoding} screenshot: ${e.message}`);
      });
      fs.writeFileSync(path.join(shots, `palette-${encoding}.png`), png);
      imgs[encoding] = decodePng(png);
      await page.close();
    }
    const n = imgs.vertices.width * imgs.vertices.height;
    const differing = changedPixels(imgs.vertices, imgs.palette, PIXEL_TOLERANCE);
    const share = differing / n;
    const fg = imageStats(imgs.palette).foreground;
    figures.push(
      `screenshots (detail, fixed pose): ${differing} of ${n} pixels differ by > ${PIXEL_TOLERANCE}/255 ` +
        `(${(100 * share).toFixed(3)}% of the canvas, ${((100 * share) / fg).toFixed(2)}% of the hand's ${(100 * fg).toFixed(1)}%)`,
    );
    assert.ok(fg > 0.01, `the palette screenshot looks blank (${(100 * fg).toFixed(2)}% foreground)`);
    assert.ok(share < MAX_DIFFERING_SHARE, `${(100 * share).toFixed(3)}% of the pixels differ (allowed ${100 * MAX_DIFFERING_SHARE}%)`);
    return `${(100 * share).toFixed(3)}% of the pixels differ by > ${PIXEL_TOLERANCE} (allowed ${100 * MAX_DIFFERING_SHARE}%)`;
  });
  const pub = await stopPublishing();
  await publisher.close();
  notes.push(
    `the fixed pose: ${pub.seq} control frames published, ${pub.acks} acks, ` +
      `${pub.superseded} superseded by a newer one, ${pub.errors.length} refused`,
  );

  await check("(i) frames drawn per second at the detail level, both encodings (demo animation)", async () => {
    await sleep(3500); // the demo animation resumes 3 s after the last foreign frame
    const rates = {};
    for (const encoding of ["vertices", "palette"]) {
      const { page } = await viewer(`level=detail&encoding=${encoding}`, `${encoding} fps page`, 1);
      await sleep(1500);
      const a = await creaseState(page);
      const t0 = Date.now();
      await sleep(5000);
      const b = await creaseState(page);
      const s = (Date.now() - t0) / 1000;
      rates[encoding] = { drawn: (b.rendered - a.rendered) / s, received: (b.frames - a.frames) / s, encoding: b.encoding };
      await page.close();
      assert.equal(b.encoding, encoding, "window.crease.encoding");
      assert.ok(b.rendered > a.rendered, `${encoding}: no frame drawn in ${s.toFixed(1)} s`);
    }
    const line = Object.entries(rates)
      .map(([k, r]) => `${k} ${r.drawn.toFixed(1)} frames/s drawn (${r.received.toFixed(1)} received)`)
      .join(", ");
    figures.push(`detail level, ~5 s each: ${line}`);
    return line;
  });
}

// Every page is closed by now: their errors were collected as they closed.
await check("no uncaught page errors", async () => {
  assert.deepEqual(pageErrors, [], `page errors:\n    ${pageErrors.join("\n    ")}`);
});
for (const n of notes) console.log(`note ${n}`);
for (const f of figures) console.log(`figure ${f}`);
const saved = shotFiles.filter((f) => fs.existsSync(path.join(shots, f)));
console.log(`screenshots: ${saved.length ? saved.map((f) => path.join(shots, f)).join(" ") : "none"}`);
console.log(`palette: ${results.length - failures()} passed, ${failures()} failed`);
process.exit(failures() ? 1 : 0);
