// WebXR hands (issue 19) in a real headless Chromium with a real WebXR runtime: Meta's emulator
// iwer (npm, `XRDevice(metaQuest3)`, `installRuntime({forceInstall: true})`, hand input) is
// installed into the viewer's page before the viewer runs; the test opens the demo's room
// `hands` (a retargeting room on the demo hand, bench/mocap/webxr-back.toml), presses "track my
// hands", drives the emulated right hand through iwer's three recorded poses
// (../shared/data/hand/iwer-pose-{relaxed,pinch,point}.js) and frames interpolated between
// them, and checks that the viewer's published marker frames reach the room and the mesh
// follows. run.sh starts the server and runs this; alone:
//   CREASE_HTTP=127.0.0.1:PORT CREASE_TOKEN=TOKEN node tests/browser/webxr.test.mjs
// Env as viewer.test.mjs (CREASE_HTTP, CREASE_TOKEN, CREASE_SHOTS, CHROMIUM).
//
// "The mesh follows", measured independently of the server's registration: per pose, the map's
// sources are evaluated here on the markers the viewer published (the targets, capture space),
// the similarity that best puts them onto the mesh's control vertices is fitted (Horn 1987,
// scale free), and the distance of every control vertex to its target after that fit is the
// figure. The same fit onto the rest hand's control points is the baseline a mesh that did not
// move would score.

import assert from "node:assert/strict";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { fileURLToPath, pathToFileURL } from "node:url";
import { chromium } from "playwright-core";
import { parse as parseToml } from "smol-toml";
import { LAUNCH_ARGS, capturePng, changedPixels, checkList, decodePng, sleep, waitForCrease, watchPage } from "./common.mjs";

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, "../..");
const httpAddr = process.env.CREASE_HTTP;
const token = process.env.CREASE_TOKEN;
if (!httpAddr || !token) {
  console.error("FAIL: set CREASE_HTTP (host:port of crease-server's HTTP side) and CREASE_TOKEN");
  process.exit(2);
}
const base = `http://${httpAddr}`;
const shots = path.resolve(
  root,
  process.env.CREASE_SHOTS || path.join(process.env.CARGO_TARGET_DIR || "target", "browser-test"),
);
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const poseDir = path.resolve(root, "../shared/data/hand");
const mapPath = path.join(root, "bench/mocap/webxr-back.toml");
const iwerBuild = path.join(here, "node_modules/iwer/build/iwer.module.js");

const ROOM = "hands";
const VIEWPORT = { width: 1024, height: 768 };
/** A control vertex may lie this far from its mapped joint target after the best similarity
 * (mm, the demo hand is in metres): what separates iwer's tracked hand from the sweep hand
 * (bone lengths, the landmarks' skin offsets, the demo model's 12 training poses). */
const MAX_FOLLOW_MM = 15;
/** ... and the frames between the recorded poses, which no example is near. */
const MAX_SWEEP_MM = 30;
/** A following mesh fits a posed hand's targets at most this fraction of the rest hand's RMS. */
const MAX_FOLLOW_TO_REST = 0.6;
/** The room's own residual (ack control_residual_capture, RMS, mm). */
const MAX_ACK_RESIDUAL_MM = 15;
/** Pixels that must differ between the pinch and the point screenshots (of 1024 x 768). */
const MIN_CHANGED_PIXELS = 2000;
const PIXEL_TOLERANCE = 16;
/** Frames interpolated between consecutive recorded poses in the sweep. */
const SWEEP_STEPS = 6;
/** Mesh frames to wait for after a pose change before measuring (the pose is applied at the
 * next XR frame; then the room's frames carry it). */
const SETTLE_FRAMES = 8;
const OVERALL_TIMEOUT_MS = 300_000;

const { check, results, failed, fail } = checkList();

if (!fs.existsSync(path.join(poseDir, "iwer-pose-pinch.js"))) {
  console.log(`skip: ${poseDir}/iwer-pose-*.js are missing (../shared/data beside the checkout)`);
  process.exit(0);
}
const poses = {
  relaxed: (await import(pathToFileURL(path.join(poseDir, "iwer-pose-relaxed.js")))).relaxedHandPose,
  pinch: (await import(pathToFileURL(path.join(poseDir, "iwer-pose-pinch.js")))).pinchHandPose,
  point: (await import(pathToFileURL(path.join(poseDir, "iwer-pose-point.js")))).pointHandPose,
};

// ---- Small 3D algebra: the sweep's interpolation and Horn's absolute orientation ---------------

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dist = (a, b) => Math.hypot(...sub(a, b));

/** The unit quaternion [x, y, z, w] of a column-major rigid 4x4's rotation (Shepperd). */
function quatOf(m) {
  const [m00, m10, m20, m01, m11, m21, m02, m12, m22] = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
  const t = m00 + m11 + m22;
  let q;
  if (t > 0) {
    const s = 2 * Math.sqrt(1 + t);
    q = [(m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, s / 4];
  } else if (m00 > m11 && m00 > m22) {
    const s = 2 * Math.sqrt(1 + m00 - m11 - m22);
    q = [s / 4, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s];
  } else if (m11 > m22) {
    const s = 2 * Math.sqrt(1 + m11 - m00 - m22);
    q = [(m01 + m10) / s, s / 4, (m12 + m21) / s, (m02 - m20) / s];
  } else {
    const s = 2 * Math.sqrt(1 + m22 - m00 - m11);
    q = [(m02 + m20) / s, (m12 + m21) / s, s / 4, (m10 - m01) / s];
  }
  const n = Math.hypot(...q);
  return q.map((v) => v / n);
}

function slerp(a, b, t) {
  let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  const bb = d < 0 ? b.map((v) => -v) : b;
  d = Math.abs(d);
  if (d > 0.9995) {
    const q = a.map((v, i) => v + t * (bb[i] - v));
    const n = Math.hypot(...q);
    return q.map((v) => v / n);
  }
  const th = Math.acos(d);
  const wa = Math.sin((1 - t) * th) / Math.sin(th);
  const wb = Math.sin(t * th) / Math.sin(th);
  return a.map((v, i) => wa * v + wb * bb[i]);
}

/** Column-major 4x4 from a unit quaternion and a translation. */
function matrixOf([x, y, z, w], p) {
  return [
    1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w), 0,
    2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w), 0,
    2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y), 0,
    p[0], p[1], p[2], 1,
  ];
}

/** An iwer hand pose between `a` and `b` (t in 0..1): per joint positions lerped, rotations
 * slerped, radii lerped. */
function between(a, b, t) {
  const out = { jointTransforms: {} };
  for (const [joint, ja] of Object.entries(a.jointTransforms)) {
    const jb = b.jointTransforms[joint];
    const p = [12, 13, 14].map((i) => ja.offsetMatrix[i] + t * (jb.offsetMatrix[i] - ja.offsetMatrix[i]));
    out.jointTransforms[joint] = {
      offsetMatrix: matrixOf(slerp(quatOf(ja.offsetMatrix), quatOf(jb.offsetMatrix), t), p),
      radius: ja.radius + t * (jb.radius - ja.radius),
    };
  }
  return out;
}

/** Eigen-decomposition of a symmetric 4x4 by cyclic Jacobi rotations: [values, vectors
 * (columns)]. */
function jacobi4(a) {
  const m = a.map((r) => r.slice());
  const v = [0, 1, 2, 3].map((i) => [0, 1, 2, 3].map((j) => (i === j ? 1 : 0)));
  for (let sweep = 0; sweep < 50; sweep++) {
    let off = 0;
    for (let p = 0; p < 4; p++) for (let q = p + 1; q < 4; q++) off += m[p][q] ** 2;
    if (off < 1e-30) break;
    for (let p = 0; p < 4; p++) {
      for (let q = p + 1; q < 4; q++) {
        if (Math.abs(m[p][q]) < 1e-300) continue;
        const theta = (m[q][q] - m[p][p]) / (2 * m[p][q]);
        const t = Math.sign(theta || 1) / (Math.abs(theta) + Math.sqrt(theta * theta + 1));
        const c = 1 / Math.sqrt(t * t + 1);
        const s = t * c;
        for (let k = 0; k < 4; k++) {
          const mkp = m[k][p], mkq = m[k][q];
          m[k][p] = c * mkp - s * mkq;
          m[k][q] = s * mkp + c * mkq;
        }
        for (let k = 0; k < 4; k++) {
          const mpk = m[p][k], mqk = m[q][k];
          m[p][k] = c * mpk - s * mqk;
          m[q][k] = s * mpk + c * mqk;
        }
        for (let k = 0; k < 4; k++) {
          const vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
    }
  }
  return [[0, 1, 2, 3].map((i) => m[i][i]), v];
}

const rotate = ([x, y, z, w], p) => {
  const m = matrixOf([x, y, z, w], [0, 0, 0]);
  return [0, 1, 2].map((r) => m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2]);
};

/** Distances of `b` to `a` under the least-squares similarity b ~ s R a + t (Horn 1987: the
 * quaternion is the top eigenvector of N built from the cross-covariance, §4; the scale the
 * asymmetric one of §2.D). */
function fittedDistances(a, b) {
  const n = a.length;
  const ca = [0, 1, 2].map((k) => a.reduce((s, p) => s + p[k], 0) / n);
  const cb = [0, 1, 2].map((k) => b.reduce((s, p) => s + p[k], 0) / n);
  const S = [[0, 0, 0], [0, 0, 0], [0, 0, 0]];
  for (let i = 0; i < n; i++) {
    const p = sub(a[i], ca), q = sub(b[i], cb);
    for (let r = 0; r < 3; r++) for (let c = 0; c < 3; c++) S[r][c] += p[r] * q[c];
  }
  const [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = S;
  const N = [
    [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
    [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
    [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
    [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
  ];
  const [values, vectors] = jacobi4(N);
  const top = values.indexOf(Math.max(...values));
  const [w, x, y, z] = [0, 1, 2, 3].map((r) => vectors[r][top]);
  const q = [x, y, z, w];
  let num = 0, den = 0;
  for (let i = 0; i < n; i++) {
    const ra = rotate(q, sub(a[i], ca));
    const bq = sub(b[i], cb);
    num += ra[0] * bq[0] + ra[1] * bq[1] + ra[2] * bq[2];
    den += ra[0] ** 2 + ra[1] ** 2 + ra[2] ** 2;
  }
  const s = num / den;
  return a.map((p, i) => {
    const ra = rotate(q, sub(p, ca));
    return dist([0, 1, 2].map((k) => s * ra[k] + cb[k]), b[i]);
  });
}

const rms = (d) => Math.sqrt(d.reduce((s, x) => s + x * x, 0) / d.length);
const mm = (x) => (1000 * x).toFixed(1);

// ---- The joint map, evaluated here ---------------------------------------------------------

const map = parseToml(fs.readFileSync(mapPath, "utf8"));
/** Per control point (model order) its target from the published markers (declared order). */
function targets(controlPoints, markerNames, markers) {
  const at = (name) => {
    const i = markerNames.indexOf(name);
    assert.ok(i >= 0, `the room declares no marker ${name}`);
    return [markers[3 * i], markers[3 * i + 1], markers[3 * i + 2]];
  };
  return controlPoints.map((c) => {
    const source = map.markers[c.name];
    assert.ok(source !== undefined, `${mapPath}: no source for ${c.name}`);
    const terms = typeof source === "string" ? { [source]: 1 } : Array.isArray(source) ? Object.fromEntries(source.map((m) => [m, 1 / source.length])) : source;
    const p = [0, 0, 0];
    for (const [name, w] of Object.entries(terms)) {
      const m = at(name);
      for (let k = 0; k < 3; k++) p[k] += w * m[k];
    }
    return p;
  });
}

// ---------------------------------------------------------------------------------------------

const watchdog = setTimeout(() => {
  console.error(`FAIL: the WebXR test did not finish within ${OVERALL_TIMEOUT_MS / 1000} s`);
  process.exit(1);
}, OVERALL_TIMEOUT_MS);

fs.mkdirSync(shots, { recursive: true });
const shotFiles = ["xr-relaxed.png", "xr-pinch.png", "xr-point.png"];
for (const f of shotFiles) fs.rmSync(path.join(shots, f), { force: true });
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "crease-chromium-"));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath,
  headless: true,
  args: LAUNCH_ARGS,
  viewport: VIEWPORT,
});
console.log(`chromium ${context.browser()?.version() ?? "(version unknown)"}; server ${base}; iwer ${JSON.parse(fs.readFileSync(path.join(here, "node_modules/iwer/package.json"))).version}`);

let pageErrors = [];
try {
  const page = context.pages()[0] ?? (await context.newPage());
  pageErrors = watchPage(page, "webxr page");
  // The emulator goes in before the viewer runs: the viewer's module as served, importing first
  // one module that installs iwer's runtime over Chromium's own navigator.xr.
  await page.route("**/__iwer/iwer.module.js", (r) =>
    r.fulfill({ body: fs.readFileSync(iwerBuild), contentType: "text/javascript" }),
  );
  await page.route("**/__iwer/install.mjs", (r) =>
    r.fulfill({
      contentType: "text/javascript",
      body: `import { XRDevice, metaQuest3 } from "/__iwer/iwer.module.js";
const device = new XRDevice(metaQuest3);
device.installRuntime({ forceInstall: true });
device.primaryInputMode = "hand";
const hand = device.hands.right;
const table = Object.getOwnPropertySymbols(hand).find((s) => s.description === "@iwer/xr-hand-input");
// An arbitrary pose: iwer reads its pose table every XR frame.
window.__setHandPose = (pose) => {
  hand[table].poses.custom = pose;
  hand.poseId = "custom";
};
window.__xrDevice = device;`,
    }),
  );
  // (The viewer's module rather than the page: a page Playwright fulfils counts as a public
  // origin for Chromium's local network access checks, which then block its WebSocket.)
  await page.route("**/viewer.js", async (r) => {
    const res = await r.fetch();
    const body = `import "/__iwer/install.mjs";\n${await res.text()}`;
    await r.fulfill({ response: res, body });
  });
  await check("(x0) a room of control points offers no hand tracking", async () => {
    await page.goto(`${base}/?room=demo`, { waitUntil: "load" });
    await waitForCrease(page, "the demo room's frames", (c) => c.connected && c.frames > 0, 30_000);
    assert.equal(await page.locator("#xr-row").isHidden(), true, "#xr-row is hidden in room demo");
  });
  // CREASE_XR_ENCODING=vertices|palette pins the stream's encoding (default: the viewer's choice).
  const encoding = process.env.CREASE_XR_ENCODING ? `&encoding=${process.env.CREASE_XR_ENCODING}` : "";
  await page.goto(`${base}/?room=${ROOM}${encoding}#token=${encodeURIComponent(token)}`, { waitUntil: "load" });
  const room = await fetch(`${base}/api/rooms/${ROOM}`).then((r) => r.json());

  await check("(x1) the viewer offers hand tracking in room hands", async () => {
    assert.ok(room.capture && room.capture.markers.length === 75, `room ${ROOM}: ${JSON.stringify(room.capture)}`);
    const c = await waitForCrease(page, "the emulated XR device", (c) => c.connected && c.vertexCount > 0 && c.xr.supported, 30_000);
    assert.equal(c.xr.reason, "", "window.crease.xr.reason");
    assert.equal(await page.locator("#xr").isEnabled(), true, "the track my hands button is enabled");
    return `${room.capture.markers.length} markers (${room.capture.units}); ${c.encoding} stream`;
  });

  await check("(x2) track my hands: an immersive session publishes every XR frame", async () => {
    await page.evaluate((p) => window.__setHandPose(p), poses.relaxed);
    await page.locator("#xr").click();
    const c = await waitForCrease(page, "published frames and their meshes", (c) => c.xr.active && c.xr.published >= 60 && c.frames >= 40, 60_000);
    assert.equal(c.error, null, "window.crease.error");
    assert.ok(c.xr.tracked, "the emulated right hand is tracked");
    assert.ok(c.acks >= c.xr.published - 30, `acks ${c.acks} for ${c.xr.published} frames`);
    return `${c.xr.published} frames published, ${c.acks} acks, ${c.frames} mesh frames, capture to mesh ${c.xr.latencyMs?.toFixed(1)} ms`;
  });

  /** Sets `pose`, waits until the room's frames carry it, and measures (see the header). */
  async function measure(pose, label) {
    const before = await page.evaluate((p) => {
      window.__setHandPose(p);
      return window.crease.xr.seq;
    }, pose);
    const c = await waitForCrease(page, `${label}: mesh frames after the pose`, (c) => c.frameSeq !== null && c.frameSeq >= before + SETTLE_FRAMES, 30_000);
    const vertices = room.control_points.map((p) => p.vertex);
    const { markers, controls, gpu } = await page.evaluate((vertices) => {
      const c = window.crease;
      // In palette mode the drawn mesh is the GPU passes' output: its control vertices, read
      // back, must be where the CPU's skinning of the same bones puts them.
      const drawn = c.encoding === "palette" && c.palette ? c.palette.readback() : null;
      return {
        markers: c.xrMarkers(),
        controls: c.controlPositions(),
        gpu: drawn && vertices.map((v) => [drawn[3 * v], drawn[3 * v + 1], drawn[3 * v + 2]]),
      };
    }, vertices);
    assert.ok(markers && controls, `${label}: no markers or no mesh`);
    assert.ok(controls.flat().every(Number.isFinite), `${label}: non-finite control vertices`);
    if (gpu) {
      const off = Math.max(...gpu.map((p, i) => dist(p, controls[i])));
      assert.ok(off < 1e-3, `${label}: the GPU-drawn control vertices are ${mm(off)} mm from the CPU's skinning`);
    }
    const goal = targets(room.control_points, room.capture.markers, markers);
    const follow = fittedDistances(goal, controls);
    const rest = fittedDistances(goal, room.control_points.map((p) => p.rest));
    const worst = follow.indexOf(Math.max(...follow));
    if (process.env.CREASE_XR_DEBUG) {
      const names = room.control_points.map((p) => p.name);
      console.log(label, names.map((n, i) => `${n} ${mm(follow[i])}/${mm(rest[i])}`).join(", "));
    }
    return { follow, rest, worst: room.control_points[worst].name, ack: c.residualCapture, errors: c.error };
  }

  const measured = {};
  for (const name of ["relaxed", "pinch", "point"]) {
    await check(`(x3) ${name}: the control vertices follow the mapped joints`, async () => {
      const m = await measure(poses[name], name);
      measured[name] = m;
      fs.writeFileSync(path.join(shots, `xr-${name}.png`), await capturePng(page, { x: 0, y: 0, ...VIEWPORT }));
      const max = Math.max(...m.follow);
      const line = `max ${mm(max)} mm at ${m.worst}, RMS ${mm(rms(m.follow))} mm (the rest hand: RMS ${mm(rms(m.rest))} mm); room residual ${mm(m.ack)} mm`;
      assert.equal(m.errors, null, "window.crease.error");
      assert.ok(max <= MAX_FOLLOW_MM / 1000, `${line}: over ${MAX_FOLLOW_MM} mm`);
      assert.ok(m.ack !== null && m.ack <= MAX_ACK_RESIDUAL_MM / 1000, `${line}: the room's residual over ${MAX_ACK_RESIDUAL_MM} mm`);
      if (name !== "relaxed") {
        assert.ok(rms(m.follow) <= MAX_FOLLOW_TO_REST * rms(m.rest), `${line}: no closer than ${MAX_FOLLOW_TO_REST} x the rest hand's`);
      }
      return line;
    });
  }

  await check("(x4) pinch and point look different", async () => {
    const [a, b] = ["xr-pinch.png", "xr-point.png"].map((f) => decodePng(fs.readFileSync(path.join(shots, f))));
    const n = changedPixels(a, b, PIXEL_TOLERANCE);
    assert.ok(n >= MIN_CHANGED_PIXELS, `${n} pixels differ (need ${MIN_CHANGED_PIXELS})`);
    return `${n} pixels differ`;
  });

  await check(`(x5) a sweep relaxed -> pinch -> point -> relaxed, ${SWEEP_STEPS} frames per leg`, async () => {
    const legs = [["relaxed", "pinch"], ["pinch", "point"], ["point", "relaxed"]];
    let worst = { d: 0 };
    let frames = 0;
    for (const [from, to] of legs) {
      for (let k = 1; k <= SWEEP_STEPS; k++) {
        const t = k / (SWEEP_STEPS + 1);
        const m = await measure(between(poses[from], poses[to], t), `${from}->${to} ${t.toFixed(2)}`);
        const d = Math.max(...m.follow);
        if (d > worst.d) worst = { d, at: `${from}->${to} t=${t.toFixed(2)} (${m.worst})` };
        assert.equal(m.errors, null, "window.crease.error");
        frames++;
      }
    }
    const c = await page.evaluate(() => JSON.parse(JSON.stringify(window.crease)));
    const line = `${frames} poses, worst ${mm(worst.d)} mm at ${worst.at}; ${c.xr.published} frames published, ${c.xr.dropped} dropped, capture to mesh ${c.xr.latencyMs?.toFixed(1)} ms`;
    assert.ok(worst.d <= MAX_SWEEP_MM / 1000, `${line}: over ${MAX_SWEEP_MM} mm`);
    return line;
  });

  await check("(x6) stop tracking ends the session", async () => {
    // The emulator's full-window canvas covers the page: the button is pressed in the DOM.
    await page.evaluate(() => document.getElementById("xr").click());
    const c = await waitForCrease(page, "the session's end", (c) => !c.xr.active, 10_000);
    assert.equal(await page.locator("#xr").textContent(), "track my hands");
    return `${c.xr.published} frames in the session`;
  });

  await check("no uncaught page errors", async () => {
    assert.deepEqual(pageErrors, [], `page errors:\n    ${pageErrors.join("\n    ")}`);
  });
} catch (e) {
  fail();
  results.push(`FAIL ${e && e.message ? e.message : e}`);
  console.log(results.at(-1));
} finally {
  await context.close().catch(() => {});
  fs.rmSync(userDataDir, { recursive: true, force: true });
  clearTimeout(watchdog);
}

const saved = shotFiles.filter((f) => fs.existsSync(path.join(shots, f)));
console.log(`screenshots: ${saved.length ? saved.map((f) => path.join(shots, f)).join(" ") : "none"}`);
console.log(`webxr: ${results.length - failed()} passed, ${failed()} failed`);
process.exit(failed() ? 1 : 0);
