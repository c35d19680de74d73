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
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";
import { parse as parseToml } from "smol-toml";
import { LAUNCH_ARGS, capturePng, changedPixels, checkList, decodePng, waitForCrease, watchPage } from "./common.mjs";
import { between, dist, fittedDistances, iwerVersion, loadPoses, mapTargets, mm, rms, routeIwer } from "./xr-common.mjs";

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

const poses = await loadPoses(poseDir);
if (!poses) process.exit(0);

const map = parseToml(fs.readFileSync(mapPath, "utf8"));
const targets = (controlPoints, markerNames, markers) => mapTargets(map, mapPath, controlPoints, markerNames, markers);

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
console.log(`chromium ${context.browser()?.version() ?? "(version unknown)"}; server ${base}; iwer ${iwerVersion()}`);

let pageErrors = [];
try {
  const page = context.pages()[0] ?? (await context.newPage());
  pageErrors = watchPage(page, "webxr page");
  // The emulator goes in before the viewer runs.
  await routeIwer(page);
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
