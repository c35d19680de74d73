// Palette streams (issue 18, issue 37's module): a PaletteTopology (rest mesh, skin, base
// triangles, the detail level's Loop level count and regressor) loaded into palette.js's
// PaletteSynth (which rebuilds the Loop steps, issue 41), then per frame the bones and the
// detail kernel vector (a codec frame of ~100 B, decoded here at once: nothing per vertex),
// synthesised on the GPU at the next redraw (latest wins). Also the
// choice of encoding (`?encoding=`, float render targets) and window.crease.palette. A room of
// several actors (issue 38) has a palette stream per actor (its slot: state.js createActor),
// each with its own PaletteSynth; window.crease.palette is the first actor's.

import { PaletteSynth, floatTargetsSupported } from "./palette.js";
import { MATERIAL_PARAMS, frameCamera, placeActor, showMesh } from "./scene.js";

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

/** The palette streams' handlers, each taking the actor's slot; `overlay` for errors and counts. */
export function createPaletteStream(state, { view, overlay }) {
  const c = state.crease;

  /** An actor's palette stream's header: everything but the bones. A second one (a new
   * socket) rebuilds. True when it began a stream. */
  function header(slot, t, bytes) {
    const received = performance.now();
    const p = slot.palette;
    if (!p.synth) p.synth = new PaletteSynth(view.renderer);
    const synth = p.synth;
    let h;
    try {
      h = synth.load(t);
    } catch (err) {
      overlay.fail(err.message);
      state.stream = null;
      if (slot.mesh) slot.mesh.visible = false;
      return false;
    }
    state.stream = "palette";
    c.headers += 1;
    // Issue 41's figures: the header read (from opening the socket), its decoding and GPU
    // set-up (the Loop rebuild included), and below the first frame shown.
    c.headerMs = Math.round(received - state.socket.openedAt);
    c.headerBytes = bytes.length;
    c.headerLoadMs = Math.round(performance.now() - received);
    c.firstFrameMs = null;
    c.encoding = "palette";
    slot.model = h.model;
    slot.vertexCount = h.vertexCount;
    p.pending = null;
    p.chain = null;
    if (!p.material) p.material = synth.material(MATERIAL_PARAMS);
    const mesh = showMesh(slot, view, synth.geometry(), p.material);
    // The shader places the vertices: the header's box is the bound, no culling needed.
    mesh.frustumCulled = false;
    mesh.visible = false; // until the first frame's passes ran
    slot.streamIndex = null; // model vertex order
    if (slot.index === 0) c.palette = { header: bytes, frame: null, frames: null, seq: null, readback: () => synth.readback() };
    return true;
  }

  /** A frame message: every actor's palette frame (`f.data` in a one-actor room, else
   * `f.actors`), decoded now (keyframe or delta), drawn at the next redraw. */
  function frame(f, bytes) {
    const list = f.actors.length ? f.actors : [{ actor: 0, data: f.data || new Uint8Array(0), held: false, placement: null }];
    for (const a of list) {
      const slot = state.actors[a.actor];
      if (!slot || !slot.palette.synth) return overlay.fail(`frame ${f.seq}: actor ${a.actor}, but the stream has ${state.actors.length} actors`);
      const p = slot.palette;
      let decoded;
      try {
        decoded = p.synth.setFrame(a.data);
      } catch (err) {
        overlay.fail(`frame ${f.seq}${f.actors.length ? ` (actor ${slot.name})` : ""}: ${err.message}`);
        return;
      }
      if (decoded.header.kind === 0) p.chain = [bytes];
      else if (p.chain && p.chain.length < MAX_CHAIN) p.chain.push(bytes);
      else p.chain = null;
      p.pending = { bytes, seq: f.seq, chain: p.chain, length: p.chain ? p.chain.length : 0, placement: a.placement };
      slot.held = a.held;
      overlay.meshFrame(slot, f.seq, f.captureTimeUs, f.serverLatencyUs, a.data.length);
    }
  }

  /** At a redraw: runs every actor's GPU passes for a new frame; true when it did. */
  function update() {
    let shown = false;
    for (const slot of state.actors) {
      const p = slot.palette;
      if (!p.synth || !p.synth.update()) continue;
      const pending = p.pending;
      if (slot.index === 0) {
        // The redraw that first shows a frame of this stream (its passes ran; the draw follows
        // in this redraw), from opening the socket.
        if (c.firstFrameMs === null) c.firstFrameMs = Math.round(performance.now() - state.socket.openedAt);
        c.palette.frame = pending.bytes;
        c.palette.frames = pending.chain && pending.chain.slice(0, pending.length);
        c.palette.seq = pending.seq;
      }
      slot.mesh.visible = true;
      slot.placement = pending.placement;
      placeActor(state, slot);
      shown = true;
    }
    if (!shown) return false;
    if (!state.mesh.framed) frameCamera(state, view);
    state.mesh.fresh = true;
    return true;
  }

  /** The socket closed: the next header rebuilds (nothing to drop before). */
  function closed() {}

  /** Actor `slot`'s drawn mesh read back from the float target (x, y, z per vertex), or null. */
  const readback = (slot) => (slot && slot.palette.synth && state.stream === "palette" ? slot.palette.synth.readback() : null);

  return { header, frame, update, closed, readback };
}
