// The overlay (issue 37): the banner (#banner: errors and the disconnect warning), the stats
// text (#stats, redrawn every frame), the rates behind it (mesh frames per second, bytes per
// frame, server latency, frames drawn per second, XR capture-to-mesh latency) and the
// tracking line that the page and the headset's panel (xr-view.js) show in an XR session.

import * as THREE from "three";
import { cameraText } from "./camera-view.js";

/** The headset panel's canvas size (pixels) and its size in the world (metres). */
const PANEL_PIXELS = [640, 96];
const PANEL_METRES = [0.24, 0.036];

/** The tracking line: the hand, the residual (mm when the capture is in metres), the latency. */
export function xrText(state) {
  const c = state.crease;
  const x = c.xr;
  const units = state.room?.capture?.units || "capture units";
  let res = "…";
  if (c.residualCapture != null && units === "m") res = `${(c.residualCapture * 1000).toFixed(1)} mm`;
  else if (c.residualCapture != null) res = `${c.residualCapture.toFixed(4)} ${units}`;
  else if (c.residual != null) res = `${c.residual.toFixed(4)} (model units)`;
  const lat = x.latencyMs == null ? "…" : `${x.latencyMs.toFixed(0)} ms`;
  const far = c.confidence > 1 ? " · outside the examples" : "";
  const seen = x.hands.length > 1 ? x.hands.map((h) => `${h.hand} ${h.tracked ? "tracked" : "not seen"}`).join(", ") : `${x.hand} hand ${x.tracked ? "tracked" : "not seen"}`;
  return `${seen}${far}\nresidual ${res} · capture to mesh ${lat}`;
}

/** A line per actor of a room of several (issue 38): name, side, model, and held. */
function actorsText(state) {
  return state.crease.actors
    .map((a) => `${a.name}${a.side ? ` (${a.side})` : ""}: ${a.model}${a.held ? " · held" : ""}${a.residual != null ? ` · residual ${a.residual.toFixed(4)}` : ""}`)
    .join("\n");
}

/** The overlay over `banner` and `stats` (elements); the headset panel is made here too. */
export function createOverlay(state, { banner, stats }) {
  const c = state.crease;
  const rates = state.rates;

  function showBanner(kind, text) {
    banner.className = kind || "";
    banner.textContent = text || "";
  }

  /** Sets window.crease.error and shows it on the banner. */
  function fail(message) {
    c.error = message;
    showBanner("error", message);
  }

  /** An actor's mesh frame shown (either encoding): the actor's seq; the room's counts (its
   * frames once, by the first actor's; the bytes of every actor's), and an XR frame's
   * capture-to-mesh time. */
  function meshFrame(slot, seq, captureTimeUs, serverLatencyUs, bytes) {
    slot.seq = seq;
    const pub = c.actors[slot.index];
    if (pub) {
      pub.frameSeq = seq;
      pub.held = slot.held;
    }
    c.bytes += bytes;
    rates.frames.bytes += bytes;
    if (slot.index !== 0) return;
    c.frameSeq = seq;
    const tracker = state.xr.tracker;
    if (tracker && tracker.firstCaptureUs !== undefined && captureTimeUs >= tracker.firstCaptureUs) {
      rates.xr.latency += (performance.timeOrigin + performance.now()) / 1000 - captureTimeUs / 1e6;
      rates.xr.frames += 1;
    }
    c.frames += 1;
    rates.frames.frames += 1;
    rates.frames.latency += serverLatencyUs;
  }

  // The overlay inside the headset: a small text panel above the hand (xr-view.js places it).
  const panelCanvas = document.createElement("canvas");
  [panelCanvas.width, panelCanvas.height] = PANEL_PIXELS;
  const panelTexture = new THREE.CanvasTexture(panelCanvas);
  const panel = new THREE.Mesh(
    new THREE.PlaneGeometry(...PANEL_METRES),
    new THREE.MeshBasicMaterial({ map: panelTexture, transparent: true, depthTest: false }),
  );
  panel.renderOrder = 20;

  function drawPanel() {
    const g = panelCanvas.getContext("2d");
    g.clearRect(0, 0, panelCanvas.width, panelCanvas.height);
    g.fillStyle = "rgba(20, 22, 26, 0.8)";
    g.fillRect(0, 0, panelCanvas.width, panelCanvas.height);
    g.fillStyle = "#e8e8e8";
    g.font = "24px system-ui, sans-serif";
    xrText(state)
      .split("\n")
      .forEach((line, i) => g.fillText(line, 14, 38 + 38 * i));
    panelTexture.needsUpdate = true;
  }

  /** Once per redraw: counts a redraw that showed a new frame, rolls the windows, writes #stats. */
  function update(now) {
    if (state.mesh.fresh) {
      c.rendered += 1;
      rates.render.rendered += 1;
      state.mesh.fresh = false;
    }
    const f = rates.frames;
    if (now - f.t >= 1000) {
      const s = (now - f.t) / 1000;
      f.fps = f.frames / s;
      f.bpf = f.bytes / Math.max(f.frames, 1);
      f.lat = f.latency / Math.max(f.frames, 1);
      f.t = now;
      f.frames = f.bytes = f.latency = 0;
    }
    const x = rates.xr;
    if (now - x.t >= 500) {
      if (x.frames) c.xr.latencyMs = (1000 * x.latency) / x.frames;
      x.t = now;
      x.frames = x.latency = 0;
      if (state.xr.tracker) drawPanel();
    }
    const r = rates.render;
    if (now - r.t >= 1000) {
      c.renderFps = r.rendered / ((now - r.t) / 1000);
      r.t = now;
      r.rendered = 0;
    }
    stats.textContent =
      `model ${c.model || "…"} · ${state.level}\n` +
      `${c.encoding} (${c.paletteReason})\n` +
      `${c.vertexCount.toLocaleString()} vertices\n` +
      `${f.fps.toFixed(1)} frames/s · ${Math.round(f.bpf).toLocaleString()} B/frame\n` +
      `${c.renderFps.toFixed(1)} frames/s drawn\n` +
      `server latency ${(f.lat / 1000).toFixed(2)} ms\n` +
      `published ${c.published} · acks ${c.acks}` +
      (c.actors.length > 1 ? `\n${actorsText(state)}` : "") +
      (c.confidence != null ? `\nconfidence ${c.confidence.toFixed(2)}${c.confidence > 1 ? " (outside the examples)" : ""}` : "") +
      (state.xr.tracker ? `\n${xrText(state)}` : state.room?.capture && c.xr.reason && !c.camera.active ? `\nWebXR: ${c.xr.reason}` : "") +
      (c.camera.active ? `\n${cameraText(c)}` : "");
  }

  return { showBanner, fail, meshFrame, update, panel };
}
