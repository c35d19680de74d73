// The HTML reports of `crease eval --report` and `crease train --report` (issue 22) in a real
// headless Chromium: every picture loads and is not blank, and every number of the page's
// tables equals the command's --json output. Plain Node ESM (node:assert + playwright-core):
// see README.md beside this file. run.sh writes the reports and runs it; alone:
//   CREASE_REPORTS=target/browser-test/report-horse,... node tests/browser/report.test.mjs
// Env: CREASE_REPORTS (comma-separated report folders, required; each holds index.html and
// stdout.json, the --json output of the run that wrote it), CREASE_SHOTS (full-page
// screenshots, report-NAME.png; default ${CARGO_TARGET_DIR:-target}/browser-test), CHROMIUM
// (default /usr/bin/chromium).
// Prints one line per check, closes on "report: N passed, N failed"; exits 1 on a failure.

import assert from "node:assert/strict";
import fs from "node:fs";
import http from "node:http";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";
import { LAUNCH_ARGS, checkList, decodePng, watchPage } from "./common.mjs";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
const target = process.env.CARGO_TARGET_DIR || "target";
const shots = path.resolve(root, process.env.CREASE_SHOTS || path.join(target, "browser-test"));
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const reports = (process.env.CREASE_REPORTS || "")
  .split(",")
  .filter(Boolean)
  .map((d) => path.resolve(root, d));
if (reports.length === 0) {
  console.error("FAIL: set CREASE_REPORTS to the report folders (each with index.html and stdout.json)");
  process.exit(2);
}

/** Pictures a report must have at least: 3 heat maps, per-pose and per-bone plots, the
 * control points, the timings. */
const MIN_IMAGES = 6;
/** "Not blank": the luminance's standard deviation over the picture, of 255. */
const MIN_STDDEV = 3;
/** ... and the share of pixels unlike the most common colour. */
const MIN_FOREGROUND = 0.01;
/** The visible text is the value rounded to 4 significant digits. */
const TEXT_TOLERANCE = 1e-3;

const TYPES = { ".html": "text/html", ".png": "image/png", ".svg": "image/svg+xml", ".json": "application/json" };

/** A static file server over `dir` on a free loopback port (the canvas reads pixels of
 * same-origin pictures only; file:// pages are each their own origin). */
function serve(dir) {
  const server = http.createServer((req, res) => {
    const rel = decodeURIComponent(new URL(req.url, "http://x").pathname);
    const file = path.join(dir, rel);
    if (!file.startsWith(dir) || !fs.existsSync(file) || !fs.statSync(file).isFile()) {
      res.writeHead(404).end();
      return;
    }
    res.writeHead(200, { "content-type": TYPES[path.extname(file)] || "application/octet-stream" });
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, "127.0.0.1", () => resolve(server)));
}

/** The number at `keys` in `json`, or undefined. */
function at(json, keys) {
  let v = json;
  for (const k of keys) {
    if (v === null || typeof v !== "object" || !(k in v)) return undefined;
    v = v[k];
  }
  return v;
}

/** Every number of `json` outside arrays, as [path, value] (object keys joined by "."). */
function leaves(json, prefix = "") {
  if (typeof json === "number") return [[prefix, json]];
  if (json === null || typeof json !== "object" || Array.isArray(json)) return [];
  return Object.entries(json).flatMap(([k, v]) => leaves(v, prefix ? `${prefix}.${k}` : k));
}

const { check, failed, results } = checkList();
const browser = await chromium.launch({ executablePath, args: LAUNCH_ARGS });
fs.mkdirSync(shots, { recursive: true });
try {
  for (const dir of reports) {
    const name = path.basename(dir);
    const json = JSON.parse(fs.readFileSync(path.join(dir, "stdout.json"), "utf8"));
    const server = await serve(dir);
    const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
    const errors = watchPage(page, name);
    try {
      await page.goto(`http://127.0.0.1:${server.address().port}/index.html`, { waitUntil: "load" });

      await check(`${name}: every picture loads and is not blank`, async () => {
        const images = await page.evaluate(async () => {
          const out = [];
          for (const img of document.images) {
            await img.decode().catch(() => {});
            const w = img.naturalWidth, h = img.naturalHeight;
            const entry = { src: img.getAttribute("src"), w, h, complete: img.complete };
            if (w > 0 && h > 0) {
              const c = document.createElement("canvas");
              c.width = w;
              c.height = h;
              const ctx = c.getContext("2d");
              ctx.fillStyle = "#fff";
              ctx.fillRect(0, 0, w, h);
              ctx.drawImage(img, 0, 0, w, h);
              // Luminance spread and the share of pixels unlike the most common colour, as
              // common.mjs's imageStats computes them (here: moving the pixels out is slow).
              const px = ctx.getImageData(0, 0, w, h).data;
              const counts = new Map();
              let sum = 0, sum2 = 0;
              for (let i = 0; i < w * h; i++) {
                const [r, g, b] = [px[4 * i], px[4 * i + 1], px[4 * i + 2]];
                const l = 0.2126 * r + 0.7152 * g + 0.0722 * b;
                sum += l;
                sum2 += l * l;
                const key = ((r >> 3) << 10) | ((g >> 3) << 5) | (b >> 3);
                counts.set(key, (counts.get(key) || 0) + 1);
              }
              const mean = sum / (w * h);
              entry.stddev = Math.sqrt(Math.max(0, sum2 / (w * h) - mean * mean));
              entry.foreground = 1 - Math.max(...counts.values()) / (w * h);
            }
            out.push(entry);
          }
          return out;
        });
        assert.ok(images.length >= MIN_IMAGES, `${images.length} pictures, expected at least ${MIN_IMAGES}`);
        const seen = [];
        for (const img of images) {
          assert.ok(img.complete && img.w > 0 && img.h > 0, `${img.src}: not loaded (${img.w}x${img.h})`);
          const s = { stddev: img.stddev, foreground: img.foreground };
          assert.ok(
            s.stddev > MIN_STDDEV && s.foreground > MIN_FOREGROUND,
            `${img.src}: blank (luminance std. deviation ${s.stddev.toFixed(2)}, ${(100 * s.foreground).toFixed(2)}% foreground)`,
          );
          seen.push(`${img.src} ${img.w}x${img.h} sd ${s.stddev.toFixed(0)}`);
        }
        return `${images.length}: ${seen.join(", ")}`;
      });

      await check(`${name}: the tables' numbers are the --json output's`, async () => {
        const cells = await page.evaluate(() =>
          Array.from(document.querySelectorAll("td[data-value]"), (td) => ({ ...td.dataset, text: td.textContent })),
        );
        assert.ok(cells.length > 0, "no numbers in the page's tables");
        const evalReport = cells.some((c) => c.protocol !== undefined);
        const onPage = new Set();
        for (const c of cells) {
          let want;
          if (evalReport) {
            const stats = at(json, [c.protocol, c.row]);
            assert.ok(stats, `${c.protocol}/${c.row}: no such row in --json`);
            want = c.key === "frames" ? stats.frames.length : stats[c.key];
            onPage.add(`${c.protocol}/${c.row}/${c.key}`);
          } else {
            want = at(json, c.path.split("."));
            onPage.add(c.path);
          }
          const where = c.path ?? `${c.protocol}/${c.row}/${c.key}`;
          assert.equal(typeof want, "number", `${where}: not a number in --json (${JSON.stringify(want)})`);
          assert.ok(Object.is(Number(c.value), want), `${where}: page ${c.value}, --json ${want}`);
          const shown = Number(c.text);
          assert.ok(
            Math.abs(shown - want) <= TEXT_TOLERANCE * Math.abs(want),
            `${where}: shows ${c.text} for ${want}`,
          );
        }
        // And nothing of --json is missing from the page.
        const wanted = evalReport
          ? Object.entries(json).flatMap(([p, rows]) =>
              Object.keys(rows).flatMap((r) => ["rms_mean", "rms_max", "us_per_frame", "frames"].map((k) => `${p}/${r}/${k}`)),
            )
          : leaves(json).map(([p]) => p);
        const missing = wanted.filter((w) => !onPage.has(w));
        assert.deepEqual(missing, [], "numbers of --json missing from the page");
        return `${cells.length} numbers, ${wanted.length} of --json all present`;
      });

      await check(`${name}: no page errors`, async () => {
        assert.deepEqual(errors, []);
      });
      const shot = path.join(shots, `report-${name}.png`);
      await page.screenshot({ path: shot, fullPage: true });
      const png = decodePng(fs.readFileSync(shot));
      console.log(`     screenshot ${path.relative(root, shot)} (${png.width}x${png.height})`);
    } finally {
      await page.close();
      server.close();
    }
  }
} finally {
  await browser.close();
}
const passed = results.filter((r) => r.startsWith("ok")).length;
console.log(`report: ${passed} passed, ${failed()} failed`);
process.exit(failed() ? 1 : 0);
