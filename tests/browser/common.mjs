// Shared by the browser tests (viewer.test.mjs, palette.test.mjs): PNG decoding of screenshots,
// image statistics, fast canvas screenshots over the DevTools protocol, Chromium's launch
// flags, and the page-error watcher.

import assert from "node:assert/strict";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";
import zlib from "node:zlib";
import { chromium } from "playwright-core";

/** Chromium's flags: headless, software GL (SwiftShader), nothing phoning home. */
export const LAUNCH_ARGS = [
  "--no-sandbox",
  "--disable-gpu",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
];

// PNG decoding (what page.screenshot returns): 8-bit grey/grey+alpha/RGB/RGBA, no interlace,
// filters 0-4 (PNG spec, section 9). Returns {width, height, rgba: Uint8Array}.

export function decodePng(buf) {
  const sig = [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a];
  assert.ok(sig.every((b, i) => buf[i] === b), "png: bad signature");
  let off = 8;
  let ihdr = null;
  const idat = [];
  while (off + 8 <= buf.length) {
    const len = buf.readUInt32BE(off);
    const type = buf.toString("latin1", off + 4, off + 8);
    const data = buf.subarray(off + 8, off + 8 + len);
    if (type === "IHDR") {
      ihdr = {
        width: data.readUInt32BE(0),
        height: data.readUInt32BE(4),
        depth: data[8],
        colour: data[9],
        interlace: data[12],
      };
    } else if (type === "IDAT") {
      idat.push(data);
    } else if (type === "IEND") {
      break;
    }
    off += 12 + len;
  }
  assert.ok(ihdr, "png: no IHDR");
  const { width, height, depth, colour, interlace } = ihdr;
  const channels = { 0: 1, 2: 3, 4: 2, 6: 4 }[colour];
  assert.ok(depth === 8 && channels && interlace === 0, `png: unsupported ${JSON.stringify(ihdr)}`);
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  assert.equal(raw.length, height * (stride + 1), "png: image data length");
  const px = new Uint8Array(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const src = y * (stride + 1) + 1;
    const row = y * stride;
    const up = row - stride;
    for (let i = 0; i < stride; i++) {
      const x = raw[src + i];
      const a = i >= channels ? px[row + i - channels] : 0;
      const b = y > 0 ? px[up + i] : 0;
      const c = i >= channels && y > 0 ? px[up + i - channels] : 0;
      let v;
      switch (filter) {
        case 0: v = x; break;
        case 1: v = x + a; break;
        case 2: v = x + b; break;
        case 3: v = x + ((a + b) >> 1); break;
        case 4: {
          const p = a + b - c;
          const pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
          v = x + (pa <= pb && pa <= pc ? a : pb <= pc ? b : c);
          break;
        }
        default: throw new Error(`png: filter ${filter} on row ${y}`);
      }
      px[row + i] = v & 0xff;
    }
  }
  if (channels === 4) return { width, height, rgba: px };
  const rgba = new Uint8Array(width * height * 4);
  for (let i = 0, j = 0; i < width * height; i++, j += channels) {
    const grey = channels <= 2;
    rgba[4 * i] = px[j];
    rgba[4 * i + 1] = grey ? px[j] : px[j + 1];
    rgba[4 * i + 2] = grey ? px[j] : px[j + 2];
    rgba[4 * i + 3] = channels === 2 ? px[j + 1] : channels === 4 ? px[j + 3] : 255;
  }
  return { width, height, rgba };
}

/** Luminance spread and the share of pixels unlike the most common colour. */
export function imageStats(img) {
  const n = img.width * img.height;
  let sum = 0, sum2 = 0;
  const counts = new Map();
  for (let i = 0; i < n; i++) {
    const [r, g, b] = img.rgba.subarray(4 * i, 4 * i + 3);
    const l = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    sum += l;
    sum2 += l * l;
    const key = ((r >> 3) << 10) | ((g >> 3) << 5) | (b >> 3);
    counts.set(key, (counts.get(key) || 0) + 1);
  }
  const mean = sum / n;
  const stddev = Math.sqrt(Math.max(0, sum2 / n - mean * mean));
  const background = Math.max(...counts.values());
  return { mean, stddev, foreground: 1 - background / n };
}

/** Pixels whose colour changed by more than `tolerance` (of 255) in some channel. */
export function changedPixels(a, b, tolerance) {
  assert.equal(a.width, b.width, "screenshot widths differ");
  assert.equal(a.height, b.height, "screenshot heights differ");
  let changed = 0;
  for (let i = 0; i < a.width * a.height; i++) {
    for (let c = 0; c < 3; c++) {
      if (Math.abs(a.rgba[4 * i + c] - b.rgba[4 * i + c]) > tolerance) {
        changed++;
        break;
      }
    }
  }
  return changed;
}

const cdpSessions = new WeakMap();

/** A PNG of the page clipped to `clip` (CSS pixels), straight from Chromium's DevTools
 * protocol: on this busy page (WebGL in software, 60 frames/s) Playwright's own screenshots
 * take 0.5-1.7 s (they wait for the page to settle), too slow for "500 ms apart"; this ~0.2 s. */
export async function capturePng(page, clip) {
  let cdp = cdpSessions.get(page);
  if (!cdp) {
    cdp = await page.context().newCDPSession(page);
    cdpSessions.set(page, cdp);
  }
  const r = await cdp.send("Page.captureScreenshot", {
    format: "png",
    optimizeForSpeed: true,
    clip: { ...clip, scale: 1 },
  });
  return Buffer.from(r.data, "base64");
}

/** A PNG of the canvas #view. */
export async function screenshotPng(page) {
  // Generous: at the detail level the page's main thread is busy for seconds at a time.
  const box = await page.locator("#view").boundingBox({ timeout: 30_000 });
  assert.ok(box && box.width > 0 && box.height > 0, `#view has no box: ${JSON.stringify(box)}`);
  return capturePng(page, box);
}

/** Collects uncaught page errors and console errors for the report. */
export function watchPage(page, label) {
  const errors = [];
  page.on("pageerror", (e) => errors.push(`${label}: uncaught ${e.message}`));
  page.on("console", (m) => {
    if (m.type() === "error" && !/favicon/.test(m.location()?.url ?? "")) {
      errors.push(`${label}: console.error ${m.text()}`);
    }
  });
  page.on("requestfailed", (r) => {
    // Requests cut short by closing the page are no fault of the viewer.
    if (r.failure()?.errorText !== "net::ERR_ABORTED") {
      errors.push(`${label}: request failed ${r.url()} ${r.failure()?.errorText}`);
    }
  });
  return errors;
}


/** A list of named checks, each run even when an earlier one failed: `check(name, fn)` prints
 * "ok name — detail (ms)" or "FAIL name: message"; `failed()` counts the failures. */
export function checkList() {
  const results = [];
  let failures = 0;
  async function check(name, fn) {
    const t0 = Date.now();
    try {
      const detail = await fn();
      results.push(`ok   ${name}${detail ? ` — ${detail}` : ""} (${Date.now() - t0} ms)`);
    } catch (e) {
      failures++;
      results.push(`FAIL ${name}: ${e && e.message ? e.message : e}`);
    }
    console.log(results.at(-1));
  }
  return { check, results, failed: () => failures, fail: () => failures++ };
}

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Polls window.crease until `pred(state)` holds; throws with the last state after `ms`. */
export async function waitForCrease(page, what, pred, ms) {
  const deadline = Date.now() + ms;
  let last;
  for (;;) {
    last = await page.evaluate(() => (window.crease ? JSON.parse(JSON.stringify(window.crease)) : null));
    if (last && pred(last)) return last;
    if (Date.now() > deadline) {
      const shown = last ? { ...last, handles: last.handles && `${last.handles.length} handles` } : last;
      throw new Error(`${what}: not within ${ms / 1000} s; window.crease = ${JSON.stringify(shown)}`);
    }
    await sleep(100);
  }
}

/**
 * One browser test's run, start to end (the rooms-of-actors tests use it): reads
 * CREASE_HTTP and the env variables named in `need` (exits 2 naming any missing), launches
 * Debian's Chromium (CHROMIUM, default /usr/bin/chromium) headless with a fresh profile at
 * `viewport`, and runs `body({page, base, shots, env, check})` on its page: `check` is
 * checkList's, `shots` the screenshot folder (CREASE_SHOTS, default
 * ${CARGO_TARGET_DIR:-target}/browser-test), `env` the needed variables by name. Then checks
 * that the page threw nothing, prints "`label`: N passed, N failed" and exits 1 on a failure;
 * a watchdog ends a run past `timeoutMs`.
 */
export async function runBrowserTest({ label, need = [], timeoutMs, viewport = { width: 1024, height: 768 }, body }) {
  const missing = ["CREASE_HTTP", ...need].filter((n) => !process.env[n]);
  if (missing.length) {
    console.error(`FAIL: set ${missing.join(" and ")} (see the test's header)`);
    process.exit(2);
  }
  const env = Object.fromEntries(need.map((n) => [n, process.env[n]]));
  const base = `http://${process.env.CREASE_HTTP}`;
  const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
  const shots = path.resolve(root, process.env.CREASE_SHOTS || path.join(process.env.CARGO_TARGET_DIR || "target", "browser-test"));
  fs.mkdirSync(shots, { recursive: true });
  const { check, results, failed, fail } = checkList();
  const watchdog = setTimeout(() => {
    console.error(`FAIL: the ${label} test did not finish within ${timeoutMs / 1000} s`);
    process.exit(1);
  }, timeoutMs);
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "crease-chromium-"));
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: LAUNCH_ARGS,
    viewport,
  });
  console.log(`chromium ${context.browser()?.version() ?? "(version unknown)"}; server ${base}`);
  try {
    const page = context.pages()[0] ?? (await context.newPage());
    const pageErrors = watchPage(page, `${label} page`);
    await body({ page, base, shots, env, check });
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
  console.log(`${label}: ${results.length - failed()} passed, ${failed()} failed`);
  process.exit(failed() ? 1 : 0);
}
