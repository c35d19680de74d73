// Vertex streams (issue 37): a Topology (decoded here: meshopt's index codec, once per
// socket), then codec frames of every vertex, decoded off the main thread by
// decode-worker.js, which also computes their normals (three.js's computeVertexNormals, to
// the bit: normals.js). The socket message's buffer goes to the worker (transferred, no copy)
// with positions and normals buffers to reuse; the decoded ones come back (transferred) and
// become the geometry's arrays at once (swapped, not copied: the ones they replace are lent
// to the worker for a later frame), so window.crease.frameSeq and the positions the handles
// read always belong together. The upload waits for the next redraw (update()): however many
// frames came in between, the newest is drawn once (latest wins), as palette frames are.
// Frames are decoded and shown in the order they came.
//
// A room of several actors (issue 38) has a Topology per actor (its slot: state.js
// createActor) and one frame message per instant holding every actor's frame: the one worker
// decodes them all and answers them together, so every actor's mesh of one instant is swapped
// in at once (one sequence number on screen).

import * as THREE from "three";
import { decodeIndices } from "./codec.js";
import { frameCamera, placeActor, showMesh } from "./scene.js";

/** Buffers of each kind kept per actor to lend the worker (more in flight allocate; extras
 * are dropped). */
const MAX_SPARES = 3;

/** The vertex stream's handlers; `overlay` for errors and counts. */
export function createVertexStream(state, { view, overlay }) {
  const c = state.crease;
  // The worker and the stream's generation (a new stream or socket starts one: answers for
  // frames of an older one are dropped), room-wide; each actor's spares and whether its
  // geometry holds arrays not yet uploaded are in its slot.
  const w = state.vertices;

  function worker() {
    if (!w.worker) {
      w.worker = new Worker(new URL("./decode-worker.js", import.meta.url), { type: "module" });
      w.worker.onmessage = (e) => decoded(e.data);
      w.worker.onerror = (e) => overlay.fail(`frame decoder: ${e.message || "the worker failed"}`);
    }
    return w.worker;
  }

  /** Keeps `positions` and `normals` to lend the worker again when they fit the actor's stream. */
  function recycle(slot, positions, normals) {
    if (!slot) return;
    const v = slot.vertices;
    const n = slot.geometry ? slot.geometry.getAttribute("position").array.length : -1;
    if (positions && positions.length === n && v.spares.positions.length < MAX_SPARES) v.spares.positions.push(positions);
    if (normals && normals.length === n && v.spares.normals.length < MAX_SPARES) v.spares.normals.push(normals);
  }

  /** An actor's Topology: its stream (every socket sends one per actor first); true when it
   * began one. The first actor's starts a new generation. */
  function header(slot, t) {
    const v = slot.vertices;
    let index;
    try {
      index = decodeIndices(t.indices, t.triangleCount, t.vertexCount);
    } catch (err) {
      overlay.fail(`topology: ${err.message}`);
      state.stream = null;
      return false;
    }
    state.stream = "vertices";
    c.headers += 1;
    if (c.encoding === "palette") {
      // A server without palette streams ignores ?encoding=palette.
      c.encoding = "vertices";
      c.paletteReason = "the server sent vertices";
    }
    c.palette = null;
    slot.model = t.model;
    slot.vertexCount = t.vertexCount;
    if (slot.index === 0) restart();
    // The worker takes the actor's triangles (copied: the geometry keeps them).
    worker().postMessage({ type: "topology", actor: slot.index, index });
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
    geo.setAttribute("normal", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
    geo.setIndex(new THREE.BufferAttribute(index, 1));
    const mesh = showMesh(slot, view, geo, view.material);
    mesh.frustumCulled = true;
    mesh.visible = true;
    for (const kind of ["positions", "normals"]) v.spares[kind] = v.spares[kind].filter((a) => a.length === 3 * t.vertexCount);
    v.dirty = false;
    // Control points index model vertices; the stream may be in its own order (base level).
    slot.streamIndex = null;
    if (t.vertexOrder.length === t.vertexCount) {
      const streamIndex = new Uint32Array(t.vertexCount);
      t.vertexOrder.forEach((model, i) => (streamIndex[model] = i));
      slot.streamIndex = streamIndex;
    }
    return true;
  }

  /** A new stream generation: results of frames sent before are dropped; the worker forgets
   * every actor's lanes and triangles. */
  function restart() {
    w.generation += 1;
    if (w.worker) w.worker.postMessage({ type: "reset" });
  }

  /** A frame message: every actor's codec frame (`f.data` in a one-actor room, else
   * `f.actors`) to the worker, with the socket message's buffer (`bytes`, transferred: each
   * part is a view of it). */
  function frame(f, bytes) {
    const list = f.actors.length ? f.actors : [{ actor: 0, data: f.data || new Uint8Array(0), held: false, placement: null }];
    const parts = [];
    const transfer = [bytes.buffer];
    for (const a of list) {
      const slot = state.actors[a.actor];
      if (!slot || !slot.geometry) return overlay.fail(`frame ${f.seq}: actor ${a.actor}, but the stream has ${state.actors.length} actors`);
      const data = a.data.buffer === bytes.buffer ? a.data : new Uint8Array(0);
      const positions = slot.vertices.spares.positions.pop() || null;
      const normals = slot.vertices.spares.normals.pop() || null;
      if (positions) transfer.push(positions.buffer);
      if (normals) transfer.push(normals.buffer);
      parts.push({ actor: a.actor, held: a.held, placement: a.placement, offset: data.byteOffset, length: data.length, positions, normals });
    }
    worker().postMessage(
      {
        type: "frame",
        generation: w.generation,
        seq: f.seq,
        captureTimeUs: f.captureTimeUs,
        serverLatencyUs: f.serverLatencyUs,
        data: bytes.buffer,
        parts,
      },
      transfer,
    );
  }

  /** The worker's answer for one frame message: every actor's mesh swapped in together. */
  function decoded(m) {
    const slotOf = (part) => state.actors[part.actor];
    if (m.generation !== w.generation) {
      for (const part of m.parts) recycle(slotOf(part), part.positions, part.normals); // an older stream's
      return;
    }
    if (m.type === "error") {
      for (const part of m.parts) recycle(slotOf(part), part.positions, part.normals);
      overlay.fail(`frame ${m.seq}: ${m.message}`);
      return;
    }
    for (const part of m.parts) {
      const slot = slotOf(part);
      const position = slot.geometry.getAttribute("position");
      if (part.positions.length !== position.array.length) {
        overlay.fail(`frame ${m.seq}: ${part.positions.length / 3} vertices for actor ${part.actor}, its topology has ${position.array.length / 3}`);
        return;
      }
    }
    for (const part of m.parts) {
      const slot = slotOf(part);
      const position = slot.geometry.getAttribute("position");
      const normal = slot.geometry.getAttribute("normal");
      // The same sizes: three.js updates the GPU buffers in place at the upload.
      recycle(slot, position.array, normal.array);
      position.array = part.positions;
      normal.array = part.normals;
      slot.vertices.dirty = true;
      slot.held = part.held;
      slot.placement = part.placement;
      overlay.meshFrame(slot, m.seq, m.captureTimeUs, m.serverLatencyUs, part.length);
    }
  }

  /** At a redraw: uploads every actor's newest positions and normals; true when it did. */
  function update() {
    let shown = false;
    for (const slot of state.actors) {
      const v = slot.vertices;
      if (!v.dirty) continue;
      v.dirty = false;
      const geometry = slot.geometry;
      geometry.getAttribute("position").needsUpdate = true;
      geometry.getAttribute("normal").needsUpdate = true;
      geometry.computeBoundingSphere();
      placeActor(state, slot);
      shown = true;
    }
    if (!shown) return false;
    if (!state.mesh.framed) frameCamera(state, view);
    state.mesh.fresh = true;
    return true;
  }

  /** The socket closed: the next stream starts from its headers. */
  function closed() {
    restart();
  }

  return { header, frame, update, closed };
}
