// Takes in a real headless Chromium (issue 22): the viewer lists room demo's takes, plays one
// back through a private replay room (frames published at the take's timing, pause, scrub to a
// frame, speed), and three.js's GLTFLoader loads the take's skinned glTF export (the server's
// /api/takes/{id}/glb, which run.sh checked is byte-identical to `crease take export`).
// run.sh records the take and runs this; alone:
//   CREASE_HTTP=127.0.0.1:PORT CREASE_TAKE=ID node tests/browser/takes.test.mjs
// Env: CREASE_HTTP (host:port of the server's HTTP side), CREASE_TAKE (a take of room demo),
// CREASE_JOB (optional: a done batch job of that take, listed by the viewer's jobs section),
// CREASE_SHOTS (screenshots; default ${CARGO_TARGET_DIR:-target}/browser-test), CHROMIUM.
// Prints one line per check and closes on "takes: N passed, N failed"; exits 1 on a failure.

import assert from "node:assert/strict";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";
import { LAUNCH_ARGS, checkList, screenshotPng, sleep, waitForCrease, watchPage } from "./common.mjs";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
const httpAddr = process.env.CREASE_HTTP;
const takeId = process.env.CREASE_TAKE;
const jobId = process.env.CREASE_JOB;
if (!httpAddr || !takeId) {
  console.error("FAIL: set CREASE_HTTP (host:port of crease-server's HTTP side) and CREASE_TAKE");
  process.exit(2);
}
const base = `http://${httpAddr}`;
const shots = path.resolve(root, process.env.CREASE_SHOTS || path.join(process.env.CARGO_TARGET_DIR || "target", "browser-test"));
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const OVERALL_TIMEOUT_MS = 180_000;

const watchdog = setTimeout(() => {
  console.error(`FAIL: the takes test did not finish within ${OVERALL_TIMEOUT_MS / 1000} s`);
  process.exit(1);
}, OVERALL_TIMEOUT_MS);

const { check, results, failed: failures, fail } = checkList();
fs.mkdirSync(shots, { recursive: true });
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "crease-chromium-"));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath,
  headless: true,
  args: LAUNCH_ARGS,
  viewport: { width: 1024, height: 768 },
});

// What the server says of the take, and its frames, fetched here (not through the page).
const listed = await fetch(`${base}/api/takes?room=demo`).then((r) => r.json());
const info = listed.takes.find((t) => t.take === takeId);
const recorded = await fetch(`${base}/api/takes/${takeId}/frames`).then((r) => r.json());
const model = await fetch(`${base}/api/rooms/demo`).then((r) => r.json());

let pageErrors = [];
try {
  await check("the server lists the take with its frames", async () => {
    assert.ok(info, `take ${takeId} in ${JSON.stringify(listed.takes.map((t) => t.take))}`);
    assert.ok(info.frames >= 10, `${info.frames} frames`);
    assert.equal(recorded.frames.length, info.frames, "GET .../frames has every frame");
    assert.equal(recorded.times.length, info.frames);
    assert.ok(recorded.times.every((t, i) => i === 0 || t > recorded.times[i - 1]), "times increase");
    return `${info.frames} frames, ${info.duration_s.toFixed(2)} s, ${info.bytes} bytes`;
  });

  const page = context.pages()[0] ?? (await context.newPage());
  pageErrors = watchPage(page, "takes page");
  await page.goto(`${base}/?room=demo&encoding=vertices`, { waitUntil: "load" });

  await check("the viewer lists room demo's takes", async () => {
    const c = await waitForCrease(page, "the takes list", (c) => c.take.list.includes(takeId), 30_000);
    await page.locator("#takes summary").click();
    const row = page.locator(`#take-list .take[data-take="${takeId}"]`);
    await row.waitFor({ timeout: 10_000 });
    const href = await row.locator("a").getAttribute("href");
    assert.equal(href, `/api/takes/${encodeURIComponent(takeId)}/glb`);
    return `${c.take.list.length} takes; row: ${(await row.textContent()).trim()}`;
  });

  if (jobId) {
    // Issue 45: run.sh ran the take as a batch job (`crease job submit --take`) on this
    // server, which has no NATS; the viewer's jobs section lists it, done, its bar full.
    await check("the viewer's jobs section lists the take's batch job, done", async () => {
      await page.locator("#jobs summary").click();
      const row = page.locator(`#job-list .job[data-job="${jobId}"]`);
      await row.waitFor({ timeout: 10_000 });
      assert.equal(await row.getAttribute("data-state"), "done");
      const bar = await row.locator("progress").evaluate((p) => [p.value, p.max]);
      assert.equal(bar[0], bar[1], `progress ${bar}`);
      assert.equal(bar[1], info.frames, "one job frame per take frame");
      const c = await page.evaluate(() => window.crease.jobs);
      assert.ok(c.some((j) => j.job === jobId && j.state === "done"), JSON.stringify(c));
      return (await row.textContent()).trim();
    });
  }

  let replayRoom = null;
  await check("play opens a private replay room and publishes the take into it", async () => {
    await Promise.all([
      page.waitForURL((u) => u.searchParams.get("take") === takeId, { timeout: 30_000 }),
      page.locator(`#take-list .take[data-take="${takeId}"] button`).click(),
    ]);
    const url = new URL(page.url());
    replayRoom = url.searchParams.get("room");
    assert.match(replayRoom, /^replay-[0-9a-f]{12}$/);
    assert.ok(!url.search.includes("token"), "the token stays out of the query");
    const rooms = await fetch(`${base}/api/rooms`).then((r) => r.json());
    assert.ok(!rooms.rooms.includes(replayRoom), `a private room is not listed: ${JSON.stringify(rooms.rooms)}`);
    const c = await waitForCrease(
      page,
      "replayed frames",
      (c) => c.take.loaded && c.take.sent >= 5 && c.acks >= 5 && c.frames >= 5,
      60_000,
    );
    assert.equal(c.room, replayRoom);
    assert.equal(c.take.frames, info.frames);
    return `room ${replayRoom}: ${c.take.sent} frames sent, ${c.acks} acks, ${c.frames} mesh frames`;
  });

  await check("the player keeps the take's timing at 1x and 4x", async () => {
    const p0 = await page.evaluate(() => ({ ...window.crease.take, now: performance.now() }));
    await sleep(1000);
    const p1 = await page.evaluate(() => ({ ...window.crease.take, now: performance.now() }));
    assert.ok(p0.playing && p1.playing, "playing throughout the second");
    const rate1 = (p1.t - p0.t) / ((p1.now - p0.now) / 1000);
    assert.ok(Math.abs(rate1 - 1) < 0.35, `the timeline moved ${rate1.toFixed(2)} s per second at 1x`);
    // From the start again (scrubbing pauses), then play at 4x.
    await page.locator("#take-scrub").fill("0");
    await page.selectOption("#take-speed", "4");
    await page.evaluate(() => document.querySelector("#player button").click());
    const a = await page.evaluate(() => ({ ...window.crease.take, now: performance.now() }));
    await sleep(500);
    const b = await page.evaluate(() => ({ ...window.crease.take, now: performance.now() }));
    const rate = (b.t - a.t) / ((b.now - a.now) / 1000);
    assert.ok(a.playing && b.playing, "playing throughout (the take lasts longer than 2 s at 4x)");
    assert.ok(rate > 2.5 && rate < 5.5, `${rate.toFixed(2)} s per second at 4x`);
    return `1x: ${rate1.toFixed(2)} s per second, 4x: ${rate.toFixed(2)}`;
  });

  await check("pause stops publishing; scrubbing sends the chosen frame and the mesh follows", async () => {
    await page.evaluate(() => {
      if (window.crease.take.playing) document.querySelector("#player button").click();
    });
    const sent = (await page.evaluate(() => window.crease.take.sent));
    await sleep(600);
    assert.equal(await page.evaluate(() => window.crease.take.sent), sent, "frames sent while paused");
    const target = Math.floor(info.frames / 3);
    await page.locator("#take-scrub").fill(String(target));
    const seq = recorded.frames[target].seq;
    const c = await waitForCrease(page, `frame ${target} (seq ${seq}) shown`, (c) => c.take.index === target && c.frameSeq === seq, 20_000);
    assert.equal(c.take.playing, false);
    fs.writeFileSync(path.join(shots, "take-replay.png"), await screenshotPng(page));
    return `frame ${target}: seq ${seq} came back as a mesh frame`;
  });

  await check("three.js's GLTFLoader loads the take's skinned glTF", async () => {
    const got = await page.evaluate(async (url) => {
      const THREE = await import("three");
      const { GLTFLoader } = await import("three/addons/loaders/GLTFLoader.js");
      const gltf = await new GLTFLoader().loadAsync(url);
      const skinned = [];
      gltf.scene.traverse((o) => o.isSkinnedMesh && skinned.push(o));
      const mesh = skinned[0];
      const clip = gltf.animations[0];
      // Vertex 0 skinned by three.js at the first and at the middle keyframe.
      const mixer = new THREE.AnimationMixer(gltf.scene);
      mixer.clipAction(clip).play();
      const at = (t) => {
        mixer.setTime(t);
        gltf.scene.updateMatrixWorld(true);
        const v = new THREE.Vector3();
        const out = [];
        for (let i = 0; i < mesh.geometry.attributes.position.count; i += 97) {
          mesh.getVertexPosition(i, v);
          out.push(v.toArray());
        }
        return out;
      };
      const first = at(0);
      const middle = at(clip.duration / 2);
      let moved = 0;
      let finite = true;
      for (let i = 0; i < first.length; i++) {
        const d = Math.hypot(...first[i].map((x, k) => x - middle[i][k]));
        moved = Math.max(moved, d);
        finite = finite && first[i].every(Number.isFinite) && middle[i].every(Number.isFinite);
      }
      return {
        skinned: skinned.length,
        bones: mesh?.skeleton.bones.length,
        vertices: mesh?.geometry.attributes.position.count,
        clips: gltf.animations.length,
        tracks: clip?.tracks.length,
        duration: clip?.duration,
        moved,
        finite,
      };
    }, `/api/takes/${encodeURIComponent(takeId)}/glb`);
    assert.equal(got.skinned, 1, "one skinned mesh");
    assert.equal(got.bones, recorded.bones, "one joint per bone");
    assert.equal(got.vertices, model.base_vertices, "the base mesh");
    assert.equal(got.clips, 1);
    assert.equal(got.tracks, 2 * got.bones, "a translation and a rotation track per joint");
    const last = recorded.times[recorded.times.length - 1];
    assert.ok(Math.abs(got.duration - last) < 1e-3, `clip ${got.duration} s, take ${last} s`);
    assert.ok(got.finite, "finite skinned positions");
    assert.ok(got.moved > 0, "the take moves the mesh");
    return `${got.bones} joints, ${got.vertices} vertices, ${got.tracks} tracks, ${got.duration.toFixed(2)} s; vertices move up to ${got.moved.toFixed(4)}`;
  });

  // Issue 38: a take of room performer (two actors) exports one glTF with both hands.
  const actorsTake = process.env.CREASE_ACTORS_TAKE;
  if (actorsTake) {
    await check("three.js's GLTFLoader loads a room of actors' take with both skinned hands", async () => {
      const got = await page.evaluate(async (url) => {
        const THREE = await import("three");
        const { GLTFLoader } = await import("three/addons/loaders/GLTFLoader.js");
        const gltf = await new GLTFLoader().loadAsync(url);
        const skinned = [];
        gltf.scene.traverse((o) => o.isSkinnedMesh && skinned.push(o));
        const clip = gltf.animations[0];
        const mixer = new THREE.AnimationMixer(gltf.scene);
        mixer.clipAction(clip).play();
        const sample = (t) => {
          mixer.setTime(t);
          gltf.scene.updateMatrixWorld(true);
          const v = new THREE.Vector3();
          return skinned.map((mesh) => {
            const out = [];
            for (let i = 0; i < mesh.geometry.attributes.position.count; i += 97) {
              mesh.getVertexPosition(i, v);
              out.push(v.toArray());
            }
            return out;
          });
        };
        const first = sample(0);
        const middle = sample(clip.duration / 2);
        const moved = first.map((hand, k) => Math.max(...hand.map((p, i) => Math.hypot(...p.map((x, j) => x - middle[k][i][j])))));
        const finite = [...first, ...middle].every((hand) => hand.every((p) => p.every(Number.isFinite)));
        // The left hand's rest mesh is the right one's mirror image across x = 0.
        const [r, l] = skinned.map((m) => m.geometry.attributes.position);
        let mirrorError = 0;
        for (let i = 0; i < r.count; i++) {
          mirrorError = Math.max(mirrorError, Math.abs(l.getX(i) + r.getX(i)), Math.abs(l.getY(i) - r.getY(i)), Math.abs(l.getZ(i) - r.getZ(i)));
        }
        return {
          names: skinned.map((m) => m.name),
          bones: skinned.map((m) => m.skeleton.bones.length),
          vertices: skinned.map((m) => m.geometry.attributes.position.count),
          tracks: clip?.tracks.length,
          moved,
          finite,
          mirrorError,
        };
      }, `/api/takes/${encodeURIComponent(actorsTake)}/glb`);
      assert.deepEqual(got.names, ["right", "left"], "a skinned mesh per actor, named after it");
      assert.deepEqual(got.bones, [recorded.bones, recorded.bones], "one joint per bone, each hand");
      assert.deepEqual(got.vertices, [model.base_vertices, model.base_vertices], "each the base mesh");
      assert.equal(got.tracks, 2 * 2 * recorded.bones, "a translation and a rotation track per joint of both");
      assert.ok(got.finite, "finite skinned positions");
      assert.ok(got.moved.every((d) => d > 0), `both hands move: ${got.moved}`);
      assert.ok(got.mirrorError < 1e-6, `the left rest mesh mirrors the right one: off by ${got.mirrorError}`);
      return `hands ${got.names.join(" and ")}, ${got.bones[0]} joints each, ${got.tracks} tracks, rest meshes mirrored to ${got.mirrorError}; moved ${got.moved.map((d) => d.toFixed(4)).join(", ")}`;
    });
  }

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
console.log(`takes: ${results.length - failures()} passed, ${failures()} failed`);
process.exit(failures() ? 1 : 0);
