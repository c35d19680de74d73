// The webcam source closed through our own hand (issue 46): the page renders the sweep hand
// (`crease handgen`'s training poses, three.js, a skin-like material, no handles, a plain
// background) into a canvas, the camera path (web/camera-view.js: MediaPipe Hands from
// web/node_modules) reads that canvas as it would a camera, and the demo's room `camera`
// retargets the landmarks through bench/mocap/mediapipe-back.toml. Per pose the test checks
// that MediaPipe found the hand and called it a right hand, how far its image landmarks are
// from the rendered joints' projections (`crease handgen`'s poses/train/*.joints.json, the
// WebXR joints MediaPipe's landmarks are), and that the room's mesh follows the published
// landmarks within the WebXR test's per-pose bounds (webxr.test.mjs says what they mean),
// printed per pose. Overall: found in at least 10 of 12 poses, landmarks within 15 px on
// average. Under headless Chromium's software GL MediaPipe takes seconds a frame, so each pose
// is shown for two of its frames. run.sh starts the server and runs this; alone:
//   CREASE_HTTP=127.0.0.1:PORT CREASE_TOKEN=TOKEN CREASE_BIN=target/release/crease node tests/browser/camera.test.mjs

import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { parse as parseToml } from "smol-toml";
import { capturePng, runBrowserTest, waitForCrease } from "./common.mjs";
import { fittedDistances, mapTargets, mm, rms } from "./xr-common.mjs";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
const MAP_PATH = path.join(root, "bench/mocap/mediapipe-back.toml");
const ROOM = "camera";
const SIZE = { width: 640, height: 480 };
const POSES = 12;
const MIN_FOUND = 10;
const MAX_MEAN_PX = 15;
// The WebXR tests' per-pose bounds (webxr.test.mjs).
const MAX_FOLLOW_MM = 15;
const MAX_FOLLOW_TO_REST = 0.6;
/** MediaPipe's landmarks as the WebXR joints they are (crease_hand::mediapipe_map). */
const AS_WEBXR = [
  "wrist",
  "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip",
  ...["index", "middle", "ring", "pinky"].flatMap((f) =>
    ["phalanx-proximal", "phalanx-intermediate", "phalanx-distal", "tip"].map((j) => `${f}-finger-${j}`),
  ),
];

/** A binary little-endian PLY as `crease handgen` writes it: float x, y, z; uchar/uint faces. */
function readPly(file) {
  const buf = fs.readFileSync(file);
  const end = buf.indexOf("end_header\n") + "end_header\n".length;
  const header = buf.toString("latin1", 0, end);
  const vertices = Number(/element vertex (\d+)/.exec(header)[1]);
  const faces = Number(/element face (\d+)/.exec(header)[1]);
  const positions = new Float32Array(3 * vertices);
  for (let i = 0; i < 3 * vertices; i++) positions[i] = buf.readFloatLE(end + 4 * i);
  const indices = new Uint32Array(3 * faces);
  let off = end + 12 * vertices;
  for (let f = 0; f < faces; f++) {
    assert.equal(buf[off], 3, `${file}: face ${f} is not a triangle`);
    for (let k = 0; k < 3; k++) indices[3 * f + k] = buf.readUInt32LE(off + 1 + 4 * k);
    off += 13;
  }
  return { positions: Array.from(positions), indices: Array.from(indices) };
}

async function checks({ page, base, shots, env, check }) {
  const work = fs.mkdtempSync(path.join(shots, "camera-"));
  execFileSync(env.CREASE_BIN, ["handgen", "--base-only", "--train", String(POSES), "--test", "1", "--out", work], { stdio: "ignore" });
  const names = fs.readdirSync(path.join(work, "base/train")).filter((f) => f.endsWith(".ply")).sort().map((f) => f.slice(0, -4));
  assert.equal(names.length, POSES, `handgen's training poses: ${names}`);
  const poses = names.map((name) => {
    const joints = JSON.parse(fs.readFileSync(path.join(work, "poses/train", `${name}.joints.json`), "utf8"));
    return { name, mesh: readPly(path.join(work, "base/train", `${name}.ply`)), landmarks: AS_WEBXR.map((j) => joints[j]) };
  });
  const map = parseToml(fs.readFileSync(MAP_PATH, "utf8"));
  const room = await fetch(`${base}/api/rooms/${ROOM}`).then((r) => r.json());
  const right = room.actors.find((a) => a.name === "right");

  await page.goto(`${base}/?room=${ROOM}#token=${encodeURIComponent(env.CREASE_TOKEN)}`, { waitUntil: "load" });
  await check("(c1) room camera: both hands' actors take MediaPipe's landmarks; the button shows", async () => {
    assert.deepEqual(room.actors.map((a) => [a.name, a.side, a.capture?.markers.length]), [["right", "right", 21], ["left", "left", 21]]);
    await waitForCrease(page, "both actors' headers", (c) => c.connected && c.actors.length === 2, 30_000);
    assert.equal(await page.locator("#camera-row").isVisible(), true, "#camera-row");
    assert.equal(await page.locator("#xr-row").isHidden(), true, "no WebXR row for MediaPipe markers");
  });

  // The stage: the hand in the hand frame (wrist at the origin, fingers along +y, palm towards
  // -z) seen from its back, 45 cm away, a 40-degree vertical field of view.
  await page.evaluate(async ({ size }) => {
    const THREE = await import("three");
    const canvas = document.createElement("canvas");
    canvas.width = size.width;
    canvas.height = size.height;
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.setSize(size.width, size.height, false);
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(0x5a6e82);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.8);
    sun.position.set(0.3, 0.5, 1);
    scene.add(sun);
    const camera = new THREE.PerspectiveCamera(40, size.width / size.height, 0.01, 10);
    camera.position.set(0, 0.09, 0.45);
    camera.lookAt(0, 0.09, 0);
    const material = new THREE.MeshStandardMaterial({ color: 0xe0ac8a, roughness: 0.7 });
    window.__camTest = { THREE, canvas, renderer, scene, camera, material, mesh: null };
  }, { size: SIZE });

  /** Renders `pose`; the joints' pixel positions. */
  const show = (pose) =>
    page.evaluate(({ mesh, landmarks, size }) => {
      const t = window.__camTest;
      const { THREE } = t;
      if (t.mesh) t.scene.remove(t.mesh);
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", new THREE.Float32BufferAttribute(mesh.positions, 3));
      geometry.setIndex(mesh.indices);
      geometry.computeVertexNormals();
      t.mesh = new THREE.Mesh(geometry, t.material);
      t.scene.add(t.mesh);
      t.renderer.render(t.scene, t.camera);
      return landmarks.map(([x, y, z]) => {
        const p = new THREE.Vector3(x, y, z).project(t.camera);
        return [((p.x + 1) / 2) * size.width, ((1 - p.y) / 2) * size.height];
      });
    }, { mesh: pose.mesh, landmarks: pose.landmarks, size: SIZE });

  const results = [];
  for (const [k, pose] of poses.entries()) {
    await check(`(c2) ${pose.name}: found, right, landmarks on the joints, the mesh follows`, async () => {
      const projected = await show(pose);
      if (k === 0) await page.evaluate(() => window.crease.camera.start(window.__camTest.canvas));
      const before = await page.evaluate(() => window.crease.camera.frames);
      // Two frames of this pose: MediaPipe's second has tracked from its first.
      const c = await waitForCrease(page, `${pose.name}: MediaPipe's frames`, (c) => c.camera.frames >= before + 2, 90_000);
      if (k === 0) fs.writeFileSync(path.join(shots, "camera-first-pose.png"), await capturePng(page, { x: 0, y: 0, width: 1024, height: 768 }));
      const hand = c.camera.hands.find((h) => h.side === "right") ?? c.camera.hands[0];
      const r = { name: pose.name, found: Boolean(hand), side: hand?.side, score: hand?.score };
      results.push(r);
      if (!hand) return `not found (${c.camera.inferenceMs.toFixed(0)} ms a frame)`;
      r.px = hand.image.reduce((s, p, i) => s + Math.hypot(p[0] - projected[i][0], p[1] - projected[i][1]), 0) / 21;
      // The room's mesh of the last published frame.
      // (The camera goes on publishing this pose meanwhile: the mesh and the markers read
      // below may be a frame newer, of the same picture.)
      const target = c.camera.seq;
      await waitForCrease(page, `${pose.name}: the room's frame ${target}`, (c) => c.actors.find((a) => a.name === "right")?.frameSeq >= target, 30_000);
      const seen = await page.evaluate(() => ({ markers: window.crease.cameraMarkers("right"), controls: window.crease.controlPositions("right") }));
      let line = `${hand.side} ${hand.score.toFixed(2)}, landmarks ${r.px.toFixed(1)} px from the joints`;
      if (seen.markers && seen.controls) {
        const goal = mapTargets(map, MAP_PATH, right.control_points, right.capture.markers, seen.markers);
        const follow = fittedDistances(goal, seen.controls);
        const rest = fittedDistances(goal, right.control_points.map((p) => p.rest));
        r.follow = Math.max(...follow);
        r.followRms = rms(follow);
        r.restRms = rms(rest);
        line += `; mesh max ${mm(r.follow)} mm, RMS ${mm(r.followRms)} mm (rest ${mm(r.restRms)})`;
        // Where the misses come from: MediaPipe's world landmarks against the true joints
        // (each set fitted onto the other by a similarity), and the map's targets of the
        // true joints against those of MediaPipe's landmarks and against the mesh.
        const truth = pose.landmarks.flat();
        const mp = [...Array(21).keys()].map((i) => seen.markers.slice(3 * i, 3 * i + 3));
        const world = fittedDistances(mp, pose.landmarks);
        const goalTruth = mapTargets(map, MAP_PATH, right.control_points, right.capture.markers, truth);
        const input = fittedDistances(goal, goalTruth);
        const toTruth = fittedDistances(seen.controls, goalTruth);
        if (process.env.CREASE_CAMERA_DUMP) fs.appendFileSync(process.env.CREASE_CAMERA_DUMP, JSON.stringify({ name: pose.name, truth: pose.landmarks, markers: seen.markers, image: hand.image, projected, controls: seen.controls }) + "\n");
        const worst = (d) => `${mm(Math.max(...d))} at ${right.control_points[d.indexOf(Math.max(...d))].name}`;
        line += `; [world landmarks to joints mean ${mm(world.reduce((s, x) => s + x, 0) / 21)} max ${mm(Math.max(...world))} at ${AS_WEBXR[world.indexOf(Math.max(...world))]}; targets to true targets max ${worst(input)}; mesh to true targets max ${worst(toTruth)}, RMS ${mm(rms(toTruth))}; mesh to targets worst ${worst(follow)}]`;
      }
      assert.equal(hand.side, "right", `${line}: handedness`);
      if (r.follow !== undefined) {
        assert.ok(r.follow <= MAX_FOLLOW_MM / 1000, `${line}: over ${MAX_FOLLOW_MM} mm`);
        if (!/flat|relaxed/.test(pose.name)) assert.ok(r.followRms <= MAX_FOLLOW_TO_REST * r.restRms, `${line}: no closer than ${MAX_FOLLOW_TO_REST} x the rest hand's`);
      }
      return line;
    });
  }

  await check(`(c3) found in at least ${MIN_FOUND} of ${POSES}, landmarks within ${MAX_MEAN_PX} px on average`, async () => {
    const found = results.filter((r) => r.found);
    const px = found.reduce((s, r) => s + r.px, 0) / Math.max(found.length, 1);
    const c = await page.evaluate(() => ({ inference: window.crease.camera.inferenceMs, convert: window.crease.camera.convertMs }));
    const line = `found in ${found.length} of ${POSES} (missed: ${results.filter((r) => !r.found).map((r) => r.name).join(", ") || "none"}), landmarks ${px.toFixed(1)} px from the joints on average; MediaPipe ${c.inference.toFixed(0)} ms a frame here, landmarks to frame ${c.convert.toFixed(2)} ms`;
    assert.ok(found.length >= MIN_FOUND, line);
    assert.ok(px <= MAX_MEAN_PX, line);
    return line;
  });
  await page.evaluate(() => window.crease.camera.stop());
}

await runBrowserTest({ label: "camera", need: ["CREASE_TOKEN", "CREASE_BIN"], timeoutMs: 600_000, body: checks });
