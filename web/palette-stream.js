// Palette streams (issue 18, issue 37's module): a PaletteTopology (rest mesh, skin, the
// detail level's Loop steps and regressor) loaded into palette.js's PaletteSynth, then per
// frame the bones and the detail kernel vector (a codec frame of ~100 B, decoded here at once:
// nothing per vertex), synthesised on the GPU at the next redraw (latest wins). Also the
// choice of encoding (`?encoding=`, float render targets) and window.crease.palette.

import { PaletteSynth, floatTargetsSupported } from "./palette.js";
import { MATERIAL_PARAMS, frameCamera, showMesh } from "./scene.js";

/** The most frame messages kept from the last keyframe on (the server keys every 600 or fewer). */
const MAX_CHAIN = 4096;

/**
 * Sets window.crease.encoding and paletteReason from the address's `?encoding=` and what the
 * renderer can do: palette where it renders into float targets, else vertices.
 */
export function chooseEncoding(state, renderer) {
  const c = state.crease;
  if (state.encodingParam === "vertices") {
    c.encoding = "vertices";
    c.paletteReason = "?encoding=vertices";
  } else if (!floatTargetsSupported(renderer)) {
    c.encoding = "vertices";
    c.paletteReason = "no float render targets";
  } else {
    c.encoding = "palette";
    c.paletteReason = state.encodingParam === "palette" ? "GPU, ?encoding=palette" : "GPU";
  }
}

/** The palette stream's handlers; `overlay` for errors and counts. */
export function createPaletteStream(state, { view, overlay }) {
  const c = state.crease;
  const p = state.palette;

  /** A palette stream's header: everything but the bones. A second one (a new socket)
   * rebuilds. True when it began a stream. */
  function header(t, bytes) {
    if (!p.synth) p.synth = new PaletteSynth(view.renderer);
    const synth = p.synth;
    let h;
    try {
      h = synth.load(t);
    } catch (err) {
      overlay.fail(err.message);
      state.stream = null;
      if (state.mesh.mesh) state.mesh.mesh.visible = false;
      return false;
    }
    state.stream = "palette";
    c.headers += 1;
    c.headerMs = Math.round(performance.now() - state.socket.openedAt);
    c.headerBytes = bytes.length;
    c.encoding = "palette";
    c.model = h.model;
    c.vertexCount = h.vertexCount;
    p.pending = null;
    p.chain = null;
    if (!p.material) p.material = synth.material(MATERIAL_PARAMS);
    const mesh = showMesh(state, view, synth.geometry(), p.material);
    // The shader places the vertices: the header's box is the bound, no culling needed.
    mesh.frustumCulled = false;
    mesh.visible = false; // until the first frame's passes ran
    state.mesh.streamIndex = null; // model vertex order
    c.palette = { header: bytes, frame: null, frames: null, seq: null, readback: () => synth.readback() };
    return true;
  }

  /** A palette frame: decoded now (keyframe or delta), drawn at the next redraw. */
  function frame(f, bytes) {
    let decoded;
    try {
      decoded = p.synth.setFrame(f.data || new Uint8Array(0));
    } catch (err) {
      overlay.fail(`frame ${f.seq}: ${err.message}`);
      return;
    }
    if (decoded.header.kind === 0) p.chain = [bytes];
    else if (p.chain && p.chain.length < MAX_CHAIN) p.chain.push(bytes);
    else p.chain = null;
    p.pending = { bytes, seq: f.seq, chain: p.chain, length: p.chain ? p.chain.length : 0 };
    overlay.meshFrame(f.seq, f.captureTimeUs, f.serverLatencyUs, f.data.length);
  }

  /** At a redraw: runs the GPU passes for a new frame; true when it did. */
  function update() {
    if (!p.synth.update()) return false;
    const pending = p.pending;
    c.palette.frame = pending.bytes;
    c.palette.frames = pending.chain && pending.chain.slice(0, pending.length);
    c.palette.seq = pending.seq;
    state.mesh.mesh.visible = true;
    if (!state.mesh.framed) frameCamera(state, view);
    state.mesh.fresh = true;
    return true;
  }

  /** The socket closed: the next header rebuilds (nothing to drop before). */
  function closed() {}

  return { header, frame, update, closed };
}
