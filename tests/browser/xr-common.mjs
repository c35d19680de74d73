// What the WebXR tests share (webxr.test.mjs: one hand in room `hands`; webxr-hands.test.mjs:
// both hands in room `both-hands`, issue 38): Meta's WebXR emulator iwer installed into the
// viewer's page, iwer's recorded hand poses, the sweep's interpolation between them, and the
// measure of "the mesh follows": a marker map evaluated on the published markers, and Horn's
// absolute orientation fitting the mesh's control vertices onto those targets.

import assert from "node:assert/strict";
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath, pathToFileURL } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const iwerBuild = path.join(here, "node_modules/iwer/build/iwer.module.js");

/** iwer's version (its package.json). */
export const iwerVersion = () => JSON.parse(fs.readFileSync(path.join(here, "node_modules/iwer/package.json"))).version;

/** iwer's three recorded poses from `poseDir` ({relaxed, pinch, point}), or null (printed)
 * when ../shared/data is not beside the checkout. */
export async function loadPoses(poseDir) {
  if (!fs.existsSync(path.join(poseDir, "iwer-pose-pinch.js"))) {
    console.log(`skip: ${poseDir}/iwer-pose-*.js are missing (../shared/data beside the checkout)`);
    return null;
  }
  return {
    relaxed: (await import(pathToFileURL(path.join(poseDir, "iwer-pose-relaxed.js")))).relaxedHandPose,
    pinch: (await import(pathToFileURL(path.join(poseDir, "iwer-pose-pinch.js")))).pinchHandPose,
    point: (await import(pathToFileURL(path.join(poseDir, "iwer-pose-point.js")))).pointHandPose,
  };
}

/**
 * Installs iwer into `page` before the viewer runs: the viewer's module as served, importing
 * first one module that installs iwer's runtime (a Quest 3, hand input) over Chromium's own
 * navigator.xr. The page then has `window.__setHandPose(pose, hand = "right")` (iwer reads its
 * pose table every XR frame; its poses are written for the left hand and mirrored onto the
 * right; each hand's pose is its own) and `window.__xrDevice`.
 */
export async function routeIwer(page) {
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
// An arbitrary pose: iwer reads its pose table every XR frame. Both hands share one table
// (the device's hand config): each hand's pose goes in under its own id.
window.__setHandPose = (pose, side = "right") => {
  const hand = device.hands[side];
  const table = Object.getOwnPropertySymbols(hand).find((s) => s.description === "@iwer/xr-hand-input");
  hand[table].poses[\`crease-\${side}\`] = pose;
  hand.poseId = \`crease-\${side}\`;
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
}

// ---- Small 3D algebra: the sweep's interpolation and Horn's absolute orientation ---------------

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
export const dist = (a, b) => Math.hypot(...sub(a, b));

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
export function between(a, b, t) {
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
export function fittedDistances(a, b) {
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

export const rms = (d) => Math.sqrt(d.reduce((s, x) => s + x * x, 0) / d.length);
export const mm = (x) => (1000 * x).toFixed(1);

// ---- The joint map, evaluated here ---------------------------------------------------------

// ---- The joint map, evaluated here ---------------------------------------------------------

/** `markers` (x, y, z per name of `markerNames`) rebuilt on the map's `[bones]`, here and
 * independently of crease_mocap::map: from the roots out, each bone's marker at its parent's
 * rebuilt place plus the bone's direction at the map's length. */
export function rebuildBones(bones, markerNames, markers) {
  const out = Array.from(markers);
  const done = new Set(markerNames.filter((n) => !(n in bones)));
  while (done.size < markerNames.length) {
    const next = markerNames.find((n) => !done.has(n) && done.has(bones[n].parent));
    assert.ok(next, `[bones] of ${markerNames.filter((n) => !done.has(n))}: no order`);
    const i = markerNames.indexOf(next), j = markerNames.indexOf(bones[next].parent);
    const d = [0, 1, 2].map((k) => markers[3 * i + k] - markers[3 * j + k]);
    const n = Math.hypot(...d);
    for (let k = 0; k < 3; k++) out[3 * i + k] = out[3 * j + k] + (d[k] * bones[next].length) / n;
    done.add(next);
  }
  return out;
}

/** Per control point (model order) its target from the published markers (declared order),
 * through the marker map `map` (parsed TOML, its `[bones]` applied first; `mapPath` names it
 * in errors). */
export function mapTargets(map, mapPath, controlPoints, markerNames, published) {
  const markers = map.bones ? rebuildBones(map.bones, markerNames, published) : published;
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

