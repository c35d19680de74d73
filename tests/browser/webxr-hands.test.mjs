// Both hands at once (issue 38) in a real headless Chromium with a real WebXR runtime (Meta's
// emulator iwer, as webxr.test.mjs): the demo's room `both-hands` holds two actors, `right` on
// the demo hand (bench/mocap/webxr-back.toml) and `left` on it mirrored across x
// (bench/mocap/webxr-back-left.toml), one performer. The test presses "track my hands", drives
// iwer's two hands through different recorded poses at once (../shared/data/hand/
// iwer-pose-{relaxed,pinch,point}.js: relaxed then pinch on one hand while the other points,
// then the other way round), and checks, per hand, that its mesh follows within the one-hand
// test's per-pose bounds, and that both meshes measured belong to the same frame (one sequence
// number: the room's frames carry both hands of an instant); and that the page draws both
// hands where the capture put them, under one registration for the performer (the server's
// placements, crease_server::performer). run.sh starts the server and runs this; alone:
//   CREASE_HTTP=127.0.0.1:PORT CREASE_TOKEN=TOKEN node tests/browser/webxr-hands.test.mjs
// Env as webxr.test.mjs (CREASE_HTTP, CREASE_TOKEN, CREASE_SHOTS, CHROMIUM, CREASE_XR_ENCODING).
//
// "The mesh follows" as in webxr.test.mjs: per hand, its actor's map evaluated on the markers
// the viewer published for that hand, the best similarity from those targets onto the actor's
// control vertices, and every control vertex's distance after it; the rest hand's the baseline.

import assert from "node:assert/strict";
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { parse as parseToml } from "smol-toml";
import { capturePng, runBrowserTest, waitForCrease } from "./common.mjs";
import { dist, fittedDistances, iwerVersion, loadPoses, mapTargets, mm, rms, routeIwer } from "./xr-common.mjs";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
const poseDir = path.resolve(root, "../shared/data/hand");
/** Each side's map, as the demo opens the room (crease-demo's both_hands_room). */
const MAPS = {
  right: path.join(root, "bench/mocap/webxr-back.toml"),
  left: path.join(root, "bench/mocap/webxr-back-left.toml"),
};

const ROOM = "both-hands";
const VIEWPORT = { width: 1024, height: 768 };
// The one-hand test's per-pose bounds (webxr.test.mjs says what each means).
const MAX_FOLLOW_MM = 15;
const MAX_FOLLOW_TO_REST = 0.6;
const MAX_ACK_RESIDUAL_MM = 15;
const SETTLE_FRAMES = 8;
/** The hands' poses, phase by phase: one hand relaxed then pinching while the other points,
 * then the other way round. */
const PHASES = [
  { right: "relaxed", left: "point" },
  { right: "pinch", left: "point" },
  { right: "point", left: "pinch" },
];

const poses = await loadPoses(poseDir);
if (!poses) process.exit(0);
const maps = Object.fromEntries(Object.entries(MAPS).map(([side, p]) => [side, parseToml(fs.readFileSync(p, "utf8"))]));

/** The checks, on the harness's page (common.mjs runBrowserTest). */
async function checks({ page, base, shots, env, check }) {
  console.log(`iwer ${iwerVersion()}`);
  const token = env.CREASE_TOKEN;
  const shotFiles = PHASES.map((p) => `xr-hands-${p.right}-${p.left}.png`);
  for (const f of shotFiles) fs.rmSync(path.join(shots, f), { force: true });
  await routeIwer(page);
  const encoding = process.env.CREASE_XR_ENCODING ? `&encoding=${process.env.CREASE_XR_ENCODING}` : "";
  await page.goto(`${base}/?room=${ROOM}${encoding}#token=${encodeURIComponent(token)}`, { waitUntil: "load" });
  const room = await fetch(`${base}/api/rooms/${ROOM}`).then((r) => r.json());
  const actors = room.actors ?? [];

  await check("(h1) room both-hands: two actors with sides; the viewer offers tracking both", async () => {
    assert.deepEqual(
      actors.map((a) => [a.name, a.side, a.performer, a.capture?.markers.length]),
      [["right", "right", "you", 75], ["left", "left", "you", 75]],
      `room ${ROOM}'s actors`,
    );
    const c = await waitForCrease(page, "both actors' stream headers and the emulated XR device", (c) => c.connected && c.actors.length === 2 && c.xr.supported, 30_000);
    assert.equal(c.xr.reason, "", "window.crease.xr.reason");
    assert.deepEqual(c.actors.map((a) => a.name), ["right", "left"], "the viewer's actors");
    assert.equal(await page.locator("#hand").isHidden(), true, "no hand to pick: both are tracked");
    return `${c.encoding} stream, models ${c.actors.map((a) => a.model).join(" and ")}`;
  });

  await check("(h2) track my hands: one message per XR frame carries both hands", async () => {
    await page.evaluate((p) => {
      window.__setHandPose(p.relaxed, "right");
      window.__setHandPose(p.relaxed, "left");
    }, poses);
    await page.evaluate(() => document.getElementById("xr").click());
    const c = await waitForCrease(page, "published frames and both hands' meshes", (c) => c.xr.active && c.xr.published >= 60 && c.frames >= 40, 60_000);
    assert.equal(c.error, null, "window.crease.error");
    assert.deepEqual(c.xr.hands.map((h) => [h.actor, h.hand, h.tracked]), [["right", "right", true], ["left", "left", true]], "both hands tracked");
    assert.ok(c.acks >= c.xr.published - 30, `acks ${c.acks} for ${c.xr.published} frames`);
    assert.ok(c.actors.every((a) => !a.held && a.frameSeq !== null), `both actors move: ${JSON.stringify(c.actors)}`);
    return `${c.xr.published} frames published, ${c.acks} acks, ${c.frames} mesh frames, capture to mesh ${c.xr.latencyMs?.toFixed(1)} ms`;
  });

  /** Sets each hand's pose, waits until the room's frames carry them, and measures both hands
   * in one look at the page (one frame). */
  async function measure(phase, label) {
    const before = await page.evaluate(
      ([right, left]) => {
        window.__setHandPose(right, "right");
        window.__setHandPose(left, "left");
        return window.crease.xr.seq;
      },
      [poses[phase.right], poses[phase.left]],
    );
    await waitForCrease(page, `${label}: mesh frames after the poses`, (c) => c.frameSeq !== null && c.frameSeq >= before + SETTLE_FRAMES, 30_000);
    const seen = await page.evaluate((actors) => {
      const c = window.crease;
      return {
        error: c.error,
        hands: actors.map((a) => {
          const drawn = c.encoding === "palette" ? c.readback(a.name) : null;
          const ack = c.actors.find((x) => x.name === a.name);
          return {
            markers: c.xrMarkers(a.name),
            controls: c.controlPositions(a.name),
            gpu: drawn && a.control_points.map((p) => [drawn[3 * p.vertex], drawn[3 * p.vertex + 1], drawn[3 * p.vertex + 2]]),
            seq: ack.frameSeq,
            held: ack.held,
            ack: ack.residualCapture,
          };
        }),
      };
    }, actors);
    const [right, left] = seen.hands;
    assert.equal(right.seq, left.seq, `${label}: the hands measured come from frames ${right.seq} and ${left.seq}`);
    return {
      seq: right.seq,
      error: seen.error,
      hands: actors.map((a, i) => {
        const h = seen.hands[i];
        assert.ok(h.markers && h.controls, `${label}: ${a.name}: no markers or no mesh`);
        assert.ok(h.controls.flat().every(Number.isFinite), `${label}: ${a.name}: non-finite control vertices`);
        assert.equal(h.held, false, `${label}: ${a.name} held its pose`);
        if (h.gpu) {
          const off = Math.max(...h.gpu.map((p, k) => dist(p, h.controls[k])));
          assert.ok(off < 1e-3, `${label}: ${a.name}: the GPU-drawn control vertices are ${mm(off)} mm from the CPU's skinning`);
        }
        const goal = mapTargets(maps[a.side], MAPS[a.side], a.control_points, a.capture.markers, h.markers);
        const follow = fittedDistances(goal, h.controls);
        const rest = fittedDistances(goal, a.control_points.map((p) => p.rest));
        const worst = a.control_points[follow.indexOf(Math.max(...follow))].name;
        return { name: a.name, follow, rest, worst, ack: h.ack };
      }),
    };
  }

  for (const [k, phase] of PHASES.entries()) {
    await check(`(h3) right ${phase.right}, left ${phase.left}: both meshes follow, in one frame`, async () => {
      const m = await measure(phase, `right ${phase.right}, left ${phase.left}`);
      fs.writeFileSync(path.join(shots, shotFiles[k]), await capturePng(page, { x: 0, y: 0, ...VIEWPORT }));
      assert.equal(m.error, null, "window.crease.error");
      const lines = m.hands.map((h) => {
        const pose = phase[h.name];
        const max = Math.max(...h.follow);
        const line = `${h.name} ${pose}: max ${mm(max)} mm at ${h.worst}, RMS ${mm(rms(h.follow))} mm (rest ${mm(rms(h.rest))}), residual ${h.ack == null ? "-" : mm(h.ack)} mm`;
        assert.ok(max <= MAX_FOLLOW_MM / 1000, `${line}: over ${MAX_FOLLOW_MM} mm`);
        assert.ok(h.ack !== null && h.ack <= MAX_ACK_RESIDUAL_MM / 1000, `${line}: the actor's residual over ${MAX_ACK_RESIDUAL_MM} mm`);
        if (pose !== "relaxed") assert.ok(rms(h.follow) <= MAX_FOLLOW_TO_REST * rms(h.rest), `${line}: no closer than ${MAX_FOLLOW_TO_REST} x the rest hand's`);
        return line;
      });
      return `frame ${m.seq}: ${lines.join("; ")}`;
    });
  }

  await check("(h4) one registration for the performer: both hands where the capture put them", async () => {
    // Where the page draws each hand's control vertices (placed by the server's performer
    // registration, in the stage) against where the capture put their targets: one similarity
    // for both hands together must fit them as well as each hand's own does. Hands laid out
    // side by side, or each registered on its own, would be centimetres off.
    const look = await page.evaluate((actors) => {
      const c = window.crease;
      return {
        placed: c.actors.map((a) => a.placed),
        seqs: c.actors.map((a) => a.frameSeq),
        hands: actors.map((a) => ({ markers: c.xrMarkers(a.name), world: c.controlPositions(a.name, true) })),
      };
    }, actors);
    assert.deepEqual(look.placed, [true, true], "both hands placed by their performer's registration");
    assert.equal(look.seqs[0], look.seqs[1], "one frame");
    const goal = [];
    const drawn = [];
    actors.forEach((a, i) => {
      goal.push(...mapTargets(maps[a.side], MAPS[a.side], a.control_points, a.capture.markers, look.hands[i].markers));
      drawn.push(...look.hands[i].world);
    });
    const together = fittedDistances(goal, drawn);
    const n = actors[0].control_points.length;
    const apart = mm(dist(goal[0], goal[n]));
    const line = `both hands under one similarity: max ${mm(Math.max(...together))} mm, RMS ${mm(rms(together))} mm (the hands' hand_top targets ${apart} mm apart)`;
    assert.ok(Math.max(...together) <= MAX_FOLLOW_MM / 1000, `${line}: over ${MAX_FOLLOW_MM} mm`);
    return line;
  });

  await check("(h5) stop tracking ends the session", async () => {
    await page.evaluate(() => document.getElementById("xr").click());
    const c = await waitForCrease(page, "the session's end", (c) => !c.xr.active, 10_000);
    return `${c.xr.published} frames in the session`;
  });
}

await runBrowserTest({ label: "webxr hands", need: ["CREASE_TOKEN"], timeoutMs: 240_000, body: checks });
