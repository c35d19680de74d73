// The viewer (web/) in a real headless Chromium against a live crease-server running its demo.
// Plain Node ESM (node:assert + playwright-core), no test framework: see README.md beside this
// file. run.sh builds and starts the server and runs this; alone:
//   CREASE_HTTP=127.0.0.1:PORT CREASE_TOKEN=TOKEN node tests/browser/viewer.test.mjs
// Env: CREASE_HTTP (host:port of the server's HTTP side, required), CREASE_TOKEN (the demo
// room's publish token, required), CREASE_SHOTS (where the screenshots go; default
// ${CARGO_TARGET_DIR:-target}/browser-test), CHROMIUM (default /usr/bin/chromium).
// Prints one line per check and closes on "browser: N passed, N failed"; exits 1 on a failure.

import assert from "node:assert/strict";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";
import { LAUNCH_ARGS, capturePng, changedPixels as changed, decodePng, imageStats, screenshotPng, watchPage, checkList, sleep, waitForCrease } from "./common.mjs";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
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
const vectorsPath = path.join(root, "tests/vectors/codec-v1.json");

const MODEL = "demo-hand";
const VIEWPORT = { width: 1024, height: 768 };
/** Std. deviation of luminance (0..255) a rendered hand must exceed (a blank canvas: ~0). */
const MIN_LUMA_STDDEV = 4;
/** Share of the canvas's pixels that must differ from its most common colour (the hand). */
const MIN_FOREGROUND = 0.01;
/** A pixel "differs" when a channel changed by more than this. */
const PIXEL_TOLERANCE = 16;
/** Pixels that must differ between two screenshots 500 ms apart (the animation moves). */
const MIN_CHANGED_PIXELS = 200;
/** The whole run's limit: a hung page or server ends the test with a clear message. */
const OVERALL_TIMEOUT_MS = 300_000;

/** Pixels whose colour changed by more than PIXEL_TOLERANCE in some channel. */
const changedPixels = (a, b) => changed(a, b, PIXEL_TOLERANCE);

// ---------------------------------------------------------------------------------------------
// Harness (common.mjs's checkList): each check runs even when an earlier one failed (unless it
// needs what failed).

const { check, results, failed: failures, fail } = checkList();
const notes = [];

async function metric(name) {
  const res = await fetch(`${base}/metrics`);
  assert.equal(res.status, 200, `GET /metrics: status ${res.status}`);
  const text = await res.text();
  const m = text.match(new RegExp(`^${name}(?:\\{[^}]*\\})? ([0-9.eE+-]+)$`, "m"));
  assert.ok(m, `GET /metrics has no ${name}`);
  return Number(m[1]);
}

/** screenshotPng, decoded; saved as `file` in the screenshot folder when given. */
async function screenshot(page, file) {
  const png = await screenshotPng(page);
  if (file) fs.writeFileSync(path.join(shots, file), png);
  return decodePng(png);
}

// ---------------------------------------------------------------------------------------------

const watchdog = setTimeout(() => {
  console.error(`FAIL: the browser test did not finish within ${OVERALL_TIMEOUT_MS / 1000} s`);
  process.exit(1);
}, OVERALL_TIMEOUT_MS);

fs.mkdirSync(shots, { recursive: true });
for (const f of ["base.png", "drag.png", "detail.png"]) fs.rmSync(path.join(shots, f), { force: true });
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "crease-chromium-"));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath,
  headless: true,
  args: LAUNCH_ARGS,
  viewport: VIEWPORT,
});
console.log(`chromium ${context.browser()?.version() ?? "(version unknown)"} at ${executablePath}; server ${base}`);

let pageErrors = [];
try {
  const page = context.pages()[0] ?? (await context.newPage());
  pageErrors = watchPage(page, "base page");
  // The token in the fragment (never sent to the server); the WebSocket carries it in its
  // subprotocols (server/src/ws.rs), never in a URL.
  const socketUrls = [];
  page.on("websocket", (ws) => socketUrls.push(ws.url()));
  await page.goto(`${base}/?room=demo#token=${encodeURIComponent(token)}`, { waitUntil: "load" });

  let live = null;
  await check("(a) frames arrive", async () => {
    const first = await waitForCrease(page, "first mesh frame", (c) => c.connected && c.frames > 0, 30_000);
    const later = await waitForCrease(page, "more frames", (c) => c.frames >= first.frames + 10, 10_000);
    live = later; // the checks below need frames, whatever else is wrong here
    assert.equal(later.connected, true, "window.crease.connected");
    assert.ok(later.vertexCount > 0, `vertexCount ${later.vertexCount}`);
    assert.equal(later.model, MODEL, "window.crease.model");
    assert.equal(later.level, "base", "window.crease.level");
    assert.equal(later.error, null, "window.crease.error");
    return (
      `${later.frames} frames, ${later.vertexCount} vertices, ${later.bytes} bytes, model ${later.model}, ` +
      `encoding ${later.encoding} (${later.paletteReason})`
    );
  });

  await check("(a2) the publish token stays out of every URL", async () => {
    assert.ok(socketUrls.length > 0, "no WebSocket opened");
    for (const u of socketUrls) assert.ok(!u.includes("token"), `a WebSocket URL carries the token: ${u}`);
    assert.ok(!page.url().includes(token), `the address bar still shows the token: ${page.url()}`);
    return `${socketUrls.length} socket(s): ${socketUrls[0]}`;
  });

  await check("(b) the canvas is not blank", async () => {
    assert.ok(live, "no frames (a)");
    await sleep(300);
    const img = await screenshot(page, "base.png");
    const s = imageStats(img);
    assert.ok(
      s.stddev > MIN_LUMA_STDDEV && s.foreground > MIN_FOREGROUND,
      `blank-looking ${img.width}x${img.height}: luminance stddev ${s.stddev.toFixed(2)} (need > ${MIN_LUMA_STDDEV}), ` +
        `${(100 * s.foreground).toFixed(2)}% unlike the background (need > ${100 * MIN_FOREGROUND}%)`,
    );
    return `${img.width}x${img.height}, luminance mean ${s.mean.toFixed(1)} stddev ${s.stddev.toFixed(1)}, ${(100 * s.foreground).toFixed(1)}% foreground`;
  });

  await check("(c) the picture moves (screenshots 500 ms apart)", async () => {
    assert.ok(live, "no frames (a)");
    // Five screenshots, each started 500 ms after the one before (or when it is done, if it
    // took longer). The demo holds each pose 0.7 s, then blends for 1.1 s (easing in and out):
    // at most two of the four pairs can fall where the hand stands (nearly) still.
    const pngs = [];
    const at = [];
    const t0 = Date.now();
    for (let i = 0; i < 5; i++) {
      if (i > 0) await sleep(Math.max(0, at[i - 1] + 500 - (Date.now() - t0)));
      at.push(Date.now() - t0);
      pngs.push(await screenshotPng(page));
    }
    const imgs = pngs.map(decodePng);
    const diffs = imgs.slice(1).map((img, i) => changedPixels(imgs[i], img));
    const moving = diffs.filter((d) => d > MIN_CHANGED_PIXELS).length;
    assert.ok(
      moving >= 2,
      `changed pixels between consecutive shots (at ${at.join(", ")} ms) ${diffs.join(", ")}: ` +
        `${moving} of 4 pairs over ${MIN_CHANGED_PIXELS}, need 2`,
    );
    return `shots at ${at.join(", ")} ms, changed pixels ${diffs.join(", ")}`;
  });

  await check("(d) dragging a handle publishes and moves the hand", async () => {
    assert.ok(live, "no frames (a)");
    const c0 = await waitForCrease(page, "handles", (c) => Array.isArray(c.handles) && c.handles.length > 0, 10_000);
    const publishedBefore = await metric("crease_frames_published_total");
    const refusedBefore = await metric("crease_frames_refused_total");
    const pageBefore = c0.published;
    // Room to drag 80 px up and look around the handle.
    const inView = (h) => h.x > 90 && h.x < VIEWPORT.width - 90 && h.y > 150 && h.y < VIEWPORT.height - 70;
    // A fingertip moves the most visibly (the demo's control points: *_nail, *_knuckle, hand_*).
    const pick = (handles) =>
      handles.find((h) => /index.*(tip|nail)/i.test(h.name)) ||
      handles.find((h) => /middle.*(tip|nail)/i.test(h.name)) ||
      handles.find((h) => /tip|nail/i.test(h.name)) ||
      handles[0];
    const handlesNow = () => page.evaluate(() => window.crease.handles);
    // The hand moves: wait for a held pose (0.7 s each) so the mouse lands on the handle, grab
    // it and move 8 px up; retried when the page published nothing (the mouse missed it).
    let h = null;
    let step1 = null;
    const missed = [];
    let seen = "";
    for (let attempt = 1; attempt <= 4 && !step1; attempt++) {
      const stillBy = Date.now() + 20_000;
      let p = await handlesNow();
      for (let still = 0; ; ) {
        await sleep(100);
        const q = await handlesNow();
        const moved = Math.max(...q.map((a, i) => Math.hypot(a.x - p[i].x, a.y - p[i].y)));
        still = moved < 1 ? still + 1 : 0;
        p = q;
        seen = JSON.stringify(q.map((a) => [a.name, Math.round(a.x), Math.round(a.y)]));
        if (still >= 2 && q.some(inView)) break;
        assert.ok(Date.now() < stillBy, `no held pose with a handle in view in 20 s; handles ${seen}`);
      }
      h = { ...pick(p.filter(inView)) };
      await page.mouse.move(h.x, h.y);
      await page.mouse.down();
      await page.mouse.move(h.x, h.y - 8);
      step1 = await waitForCrease(page, "", (c) => c.published > pageBefore && c.acks > c0.acks, 2_000).catch(
        () => null,
      );
      if (!step1) {
        await page.mouse.up();
        missed.push(`${h.name} at (${h.x.toFixed(0)}, ${h.y.toFixed(0)})`);
      }
    }
    if (missed.length) notes.push(`drag: the mouse missed ${missed.join(", ")} (nothing published)`);
    assert.ok(step1, `4 tries to grab a handle published nothing: pressed ${missed.join(", ")}; handles ${seen}`);
    // Around the handle and the 80 px above it.
    const clip = {
      x: Math.min(Math.max(0, Math.round(h.x) - 80), VIEWPORT.width - 160),
      y: Math.min(Math.max(0, Math.round(h.y) - 140), VIEWPORT.height - 200),
      width: 160,
      height: 200,
    };
    // The rest of 10 steps of 8 px up. The first frame the page published paused the demo
    // animation (it yields to other publishers for 3 s), so from the first step on the hand
    // moves only because of the drag: the region after step 1 and after step 10 must differ.
    await sleep(300);
    const regionStart = decodePng(await capturePng(page, clip));
    for (let i = 2; i <= 10; i++) {
      await sleep(50);
      await page.mouse.move(h.x, h.y - 8 * i);
    }
    // Every drag frame acked, and mesh frames (the hand the model predicts) came back.
    const held = await waitForCrease(
      page,
      "acks of the drag",
      (c) => c.acks >= c.published && c.frames > step1.frames,
      5_000,
    ).catch(() => null);
    await sleep(300);
    const regionEnd = decodePng(await capturePng(page, clip));
    await screenshot(page, "drag.png");
    await page.mouse.up();
    // Released, the handle shows its control point on the mesh again: where the model put it
    // for the last frame the page published (the demo still yields for ~2 s).
    await sleep(300);
    const after = await page.evaluate(() => JSON.parse(JSON.stringify(window.crease)));
    const publishedAfter = await metric("crease_frames_published_total");
    const refusedAfter = await metric("crease_frames_refused_total");
    const sent = after.published - pageBefore;
    assert.ok(sent >= 2, `window.crease.published grew by ${sent} (${pageBefore} -> ${after.published})`);
    assert.ok(after.acks > 0, `window.crease.acks ${after.acks}`);
    assert.ok(
      held,
      `5 s after the drag: acks ${after.acks} of ${after.published} published frames, ` +
        `mesh frames ${step1.frames} at drag step 1, ${after.frames} after`,
    );
    assert.ok(
      publishedAfter - publishedBefore >= sent,
      `crease_frames_published_total grew by ${publishedAfter - publishedBefore}, the page sent ${sent}`,
    );
    assert.equal(refusedAfter, refusedBefore, "crease_frames_refused_total grew: the server refused frames");
    assert.equal(after.error, null, "window.crease.error after the drag");
    const moved = after.handles.find((d) => d.id === h.id);
    assert.ok(moved, `handle ${h.id} (${h.name}) gone after the drag`);
    const rose = h.y - moved.y;
    const region = changedPixels(regionStart, regionEnd);
    assert.ok(
      rose > 20 && region > MIN_CHANGED_PIXELS,
      `handle ${h.name} at (${h.x.toFixed(0)}, ${h.y.toFixed(0)}) dragged 80 px up, released, is on the mesh at ` +
        `(${moved.x.toFixed(0)}, ${moved.y.toFixed(0)}): rose ${rose.toFixed(1)} px (need > 20); ` +
        `${region} pixels around it changed from drag step 1 to 10 (need > ${MIN_CHANGED_PIXELS})`,
    );
    return (
      `${h.name} (${h.x.toFixed(0)}, ${h.y.toFixed(0)}) dragged to (${h.x.toFixed(0)}, ${(h.y - 80).toFixed(0)}), ` +
      `on the mesh after release at (${moved.x.toFixed(0)}, ${moved.y.toFixed(0)}); page sent ${sent} frames, ` +
      `${after.acks} acks, server published +${publishedAfter - publishedBefore}; ` +
      `${region} pixels changed around the handle from drag step 1 to 10`
    );
  });

  await check("(e) codec test vectors decode exactly with /codec.js", async () => {
    const vectors = JSON.parse(fs.readFileSync(vectorsPath, "utf8"));
    const r = await page.evaluate(async (v) => {
      const codec = await import("/codec.js");
      await codec.ready;
      const bad = [];
      const notes = [];
      let checked = 0;
      const hex = (s) => Uint8Array.from((s.match(/../g) || []).map((h) => parseInt(h, 16)));
      // Floats are strings: the shortest decimal of an f32, or NaN / Infinity / -Infinity.
      const f32 = (s) => Math.fround(Number(s));
      // Bit-exact for f32 values: Object.is tells -0 from 0 and NaN equals NaN.
      const same = (a, e) => Object.is(Math.fround(a), f32(e));
      const cmpFloats = (what, got, want) => {
        const flat = want.flat();
        if (!got || got.length !== flat.length) {
          bad.push(`${what}: length ${got && got.length}, expected ${flat.length}`);
          return;
        }
        for (let i = 0; i < flat.length; i++) {
          if (!same(got[i], flat[i])) {
            bad.push(`${what}[${i}]: ${got[i]}, expected ${flat[i]}`);
            return;
          }
        }
      };
      const cmpInts = (what, got, want) => {
        const flat = want.flat();
        if (!got || got.length !== flat.length) {
          bad.push(`${what}: length ${got && got.length}, expected ${flat.length}`);
          return;
        }
        for (let i = 0; i < flat.length; i++) {
          if (got[i] !== flat[i]) {
            bad.push(`${what}[${i}]: ${got[i]}, expected ${flat[i]}`);
            return;
          }
        }
      };
      let normalsUnchecked = 0;
      for (const s of v.streams) {
        let prev = null;
        for (const f of s.frames) {
          const what = `stream ${s.name} frame ${f.seq}`;
          let r;
          try {
            r = codec.decodeFrame(hex(f.frame_hex), prev);
          } catch (e) {
            bad.push(`${what}: threw ${e.message}`);
            prev = null;
            continue;
          }
          const h = r.header;
          const kind = f.kind === "key" ? 0 : 1;
          if (h.kind !== kind && h.kind !== f.kind) bad.push(`${what}: kind ${h.kind}, expected ${f.kind}`);
          if (h.seq !== f.seq) bad.push(`${what}: seq ${h.seq}, expected ${f.seq}`);
          if (h.baseSeq !== f.base) bad.push(`${what}: baseSeq ${h.baseSeq}, expected ${f.base}`);
          if (h.vertexCount !== s.vertex_count) bad.push(`${what}: vertexCount ${h.vertexCount}, expected ${s.vertex_count}`);
          if (h.bits !== s.box.bits) bad.push(`${what}: bits ${h.bits}, expected ${s.box.bits}`);
          if (Boolean(h.normals) !== (f.normals !== null)) bad.push(`${what}: normals flag ${h.normals}`);
          cmpFloats(`${what} header.min`, h.min, s.box.min);
          cmpFloats(`${what} header.step`, h.step, s.box.step);
          cmpInts(`${what} lanes`, r.lanes, f.lanes);
          cmpFloats(`${what} positions`, r.positions, f.decoded_positions);
          if (f.decoded_normals) {
            if (r.normals) cmpFloats(`${what} normals`, r.normals, f.decoded_normals);
            else normalsUnchecked++;
          }
          checked++;
          prev = r.lanes;
        }
      }
      if (normalsUnchecked) {
        notes.push(`${normalsUnchecked} frames' decoded_normals not compared: decodeFrame returns no normals (their lanes w are)`);
      }
      for (const ix of v.indices) {
        const what = `indices ${ix.name}`;
        try {
          cmpInts(what, codec.decodeIndices(hex(ix.encoded_hex), ix.triangle_count, ix.vertex_count), ix.decoded_triangles);
          checked++;
        } catch (e) {
          bad.push(`${what}: threw ${e.message}`);
        }
      }
      // A keyframe of the first stream: the state of a decoder that holds 4 vertices.
      const held = codec.decodeFrame(hex(v.streams[0].frames[0].frame_hex), null).lanes;
      for (const m of v.malformed) {
        const what = `malformed "${m.about}" (${m.error})`;
        const prev = m.error === "MissingBase" ? null : held;
        try {
          const r = codec.decodeFrame(hex(m.frame_hex), prev);
          if (m.error === "VertexCount" && r.header.vertexCount !== m.vertex_count) {
            // Stateless: decodeFrame cannot know the mesh's vertex count; it must at least
            // report the frame's own so the caller can refuse it.
            notes.push(`${what}: decoded, header.vertexCount ${r.header.vertexCount} (the caller must compare)`);
            checked++;
          } else {
            bad.push(`${what}: decoded without an error`);
          }
        } catch (e) {
          if (!(e instanceof Error) || !e.message) bad.push(`${what}: threw ${e} (no Error with a message)`);
          else checked++;
        }
      }
      return { bad, notes, checked };
    }, vectors);
    notes.push(...r.notes.map((n) => `codec: ${n}`));
    assert.deepEqual(r.bad, [], `mismatches:\n    ${r.bad.join("\n    ")}`);
    const total =
      vectors.streams.reduce((n, s) => n + s.frames.length, 0) + vectors.indices.length + vectors.malformed.length;
    assert.equal(r.checked, total, `checked ${r.checked} of ${total} cases`);
    return `${r.checked} cases (frames, index buffers, malformed frames)`;
  });

  await page.close();

  const detail = await context.newPage();
  const detailErrors = watchPage(detail, "detail page");
  await check("(f) the detail level", async () => {
    await detail.goto(`${base}/?room=demo&level=detail`, { waitUntil: "load" });
    const first = await waitForCrease(detail, "first detail frame", (c) => c.connected && c.frames > 0, 60_000);
    const later = await waitForCrease(detail, "more detail frames", (c) => c.frames >= first.frames + 3, 30_000);
    assert.equal(later.level, "detail", "window.crease.level");
    assert.equal(later.model, MODEL, "window.crease.model");
    assert.ok(later.vertexCount > 100_000, `vertexCount ${later.vertexCount} (need > 100000)`);
    assert.equal(later.error, null, "window.crease.error");
    await sleep(500);
    const img = await screenshot(detail, "detail.png");
    const s = imageStats(img);
    assert.ok(
      s.stddev > MIN_LUMA_STDDEV && s.foreground > MIN_FOREGROUND,
      `blank-looking detail canvas: luminance stddev ${s.stddev.toFixed(2)}, ${(100 * s.foreground).toFixed(2)}% foreground`,
    );
    return `${later.frames} frames, ${later.vertexCount} vertices, luminance stddev ${s.stddev.toFixed(1)}`;
  });
  pageErrors.push(...detailErrors);

  // Banners and the room picker, each on a page of its own.
  const other = await context.newPage();
  pageErrors.push(...watchPage(other, "banner page"));
  const restControls = async () => {
    const info = await fetch(`${base}/api/rooms/demo`).then((r) => r.json());
    return info.control_points.flatMap((c) => c.rest);
  };
  await check("(g) a wrong token shows the bad-token banner", async () => {
    await other.goto(`${base}/?room=demo#token=not-the-token`, { waitUntil: "load" });
    await waitForCrease(other, "frames", (c) => c.connected && c.frames > 0, 30_000);
    const refusedBefore = await metric("crease_frames_refused_total");
    const flat = await restControls();
    await other.evaluate((flat) => window.crease.publish(flat), flat);
    const c = await waitForCrease(other, "the refusal's ack", (c) => c.acks > 0, 10_000);
    assert.equal(c.error, "publish refused: wrong or missing token", "window.crease.error");
    const banner = other.locator("#banner");
    assert.equal(await banner.getAttribute("class"), "error", "#banner class");
    assert.equal(await banner.textContent(), "publish refused: wrong or missing token", "#banner text");
    assert.ok(await banner.isVisible(), "#banner is visible");
    assert.ok((await metric("crease_frames_refused_total")) > refusedBefore, "the server refused the frame");
    // The page's query form (old links) is taken out of the address bar and still works.
    await other.goto(`${base}/?room=demo&token=not-the-token`, { waitUntil: "load" });
    await waitForCrease(other, "frames", (c) => c.connected && c.frames > 0, 30_000);
    assert.ok(!other.url().includes("not-the-token"), `the address bar keeps the token: ${other.url()}`);
    assert.equal(await other.locator("#token").inputValue(), "not-the-token", "the token field");
    return (await banner.textContent()) ?? "";
  });

  await check("(h) a dropped socket shows the disconnect banner, then reconnects", async () => {
    // The socket passes through to the server until the test closes it from the server side.
    let routed = null;
    await other.routeWebSocket(/\/ws\/rooms\//, (ws) => {
      ws.connectToServer();
      routed = ws;
    });
    await other.goto(`${base}/?room=demo`, { waitUntil: "load" });
    const before = await waitForCrease(other, "frames", (c) => c.connected && c.frames > 0, 30_000);
    assert.ok(routed, "the page's socket was not routed");
    // Every state the banner takes (the reconnection comes 0.5 s later and clears it).
    await other.evaluate(() => {
      const banner = document.getElementById("banner");
      window.bannerLog = [];
      new MutationObserver(() => window.bannerLog.push([banner.className, banner.textContent])).observe(banner, {
        attributes: true,
        childList: true,
        characterData: true,
        subtree: true,
      });
    });
    await routed.close({ code: 1011, reason: "server restarting" });
    const after = await waitForCrease(other, "the reconnection", (c) => c.connected && c.sockets > before.sockets && c.frames > before.frames, 30_000);
    const log = await other.evaluate(() => window.bannerLog);
    const shown = log.find(([kind]) => kind === "warn");
    assert.ok(shown, `the banner never showed the disconnect: ${JSON.stringify(log)}`);
    assert.ok(/^disconnected: server restarting — reconnecting in [0-9.]+ s$/.test(shown[1]), `#banner text: ${shown[1]}`);
    const text = shown[1];
    const banner = other.locator("#banner");
    assert.equal(await banner.textContent(), "", "the banner clears on reconnection");
    await other.unrouteAll({ behavior: "ignoreErrors" });
    return `${text}; reconnected (socket ${after.sockets})`;
  });

  await check("(i) the room picker lists the rooms and switches to another", async () => {
    await other.goto(`${base}/?room=demo`, { waitUntil: "load" });
    await waitForCrease(other, "frames", (c) => c.connected && c.frames > 0, 30_000);
    const listed = await fetch(`${base}/api/rooms`).then((r) => r.json());
    const options = await other.locator("#room option").evaluateAll((os) => os.map((o) => o.value));
    assert.deepEqual([...options].sort(), [...listed.rooms].sort(), "the picker's rooms");
    const target = listed.rooms.find((r) => r !== "demo");
    assert.ok(target, `a second room to switch to: ${JSON.stringify(listed.rooms)}`);
    await Promise.all([other.waitForNavigation({ waitUntil: "load" }), other.selectOption("#room", target)]);
    assert.equal(new URL(other.url()).searchParams.get("room"), target, "the page's room");
    // Its stream's header (a room nobody publishes into, as the demo's hands room, has no frames).
    const c = await waitForCrease(other, `room ${target}'s stream`, (c) => c.connected && c.headers > 0 && c.room === target, 60_000);
    assert.equal(await other.locator("#room").inputValue(), target, "the picker shows the new room");
    return `${options.join(", ")} -> ${target} (its ${c.encoding} stream, ${c.vertexCount} vertices)`;
  });
  await other.close();

  await check("no uncaught page errors", async () => {
    assert.deepEqual(pageErrors, [], `page errors:\n    ${pageErrors.join("\n    ")}`);
  });
} catch (e) {
  // Outside a check: the page did not load, the browser died.
  fail();
  results.push(`FAIL ${e && e.message ? e.message : e}`);
  console.log(results.at(-1));
} finally {
  await context.close().catch(() => {});
  fs.rmSync(userDataDir, { recursive: true, force: true });
  clearTimeout(watchdog);
}

for (const n of notes) console.log(`note ${n}`);
const saved = ["base.png", "drag.png", "detail.png"].filter((f) => fs.existsSync(path.join(shots, f)));
console.log(`screenshots: ${saved.length ? saved.map((f) => path.join(shots, f)).join(" ") : "none"}`);
console.log(`browser: ${results.length - failures()} passed, ${failures()} failed`);
process.exit(failures() ? 1 : 0);
