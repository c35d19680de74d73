// Vertex streams (issue 37): a Topology (decoded here: meshopt's index codec, once per
// socket), then codec frames of every vertex, decoded off the main thread by
// decode-worker.js. The socket message's buffer goes to the worker (transferred, no copy) with
// a positions buffer to reuse; the decoded positions come back (transferred) and become the
// geometry's position array at once (the array is swapped, not copied: the one it replaces is
// lent to the worker for a later frame), so window.crease.frameSeq and the positions the
// handles read always belong together. The upload and the CPU normals wait for the next
// redraw (update()): however many frames came in between, the newest is drawn once (latest
// wins), as palette frames are. Frames are decoded and shown in the order they came.

import * as THREE from "three";
import { decodeIndices } from "./codec.js";
import { frameCamera, showMesh } from "./scene.js";

/** Positions buffers kept to lend the worker (more in flight allocate; extras are dropped). */
const MAX_SPARES = 3;

/** The vertex stream's handlers; `overlay` for errors and counts. */
export function createVertexStream(state, { view, overlay }) {
  const c = state.crease;
  const v = state.vertices;

  function worker() {
    if (!v.worker) {
      v.worker = new Worker(new URL("./decode-worker.js", import.meta.url), { type: "module" });
      v.worker.onmessage = (e) => decoded(e.data);
      v.worker.onerror = (e) => overlay.fail(`frame decoder: ${e.message || "the worker failed"}`);
    }
    return v.worker;
  }

  /** Keeps `positions` to lend the worker again when it fits the current stream. */
  function recycle(positions) {
    const geometry = state.mesh.geometry;
    if (!positions || !geometry || v.spares.length >= MAX_SPARES) return;
    if (positions.length === geometry.getAttribute("position").array.length) v.spares.push(positions);
  }

  /** A Topology: a new stream (every socket sends one first); true when it began one. */
  function header(t) {
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
    c.model = t.model;
    c.vertexCount = t.vertexCount;
    restart();
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
    geo.setIndex(new THREE.BufferAttribute(index, 1));
    const mesh = showMesh(state, view, geo, view.material);
    mesh.frustumCulled = true;
    mesh.visible = true;
    v.spares = v.spares.filter((p) => p.length === 3 * t.vertexCount);
    v.dirty = false;
    // Control points index model vertices; the stream may be in its own order (base level).
    state.mesh.streamIndex = null;
    if (t.vertexOrder.length === t.vertexCount) {
      const streamIndex = new Uint32Array(t.vertexCount);
      t.vertexOrder.forEach((model, i) => (streamIndex[model] = i));
      state.mesh.streamIndex = streamIndex;
    }
    return true;
  }

  /** A new stream generation: results of frames sent before are dropped; the worker forgets its lanes. */
  function restart() {
    v.generation += 1;
    if (v.worker) v.worker.postMessage({ type: "reset" });
  }

  /** A codec frame: to the worker, with the socket message's buffer (`bytes`, transferred). */
  function frame(f, bytes) {
    const data = f.data || new Uint8Array(0);
    const positions = v.spares.pop() || null;
    const transfer = data.buffer === bytes.buffer ? [bytes.buffer] : [];
    if (positions) transfer.push(positions.buffer);
    worker().postMessage(
      {
        type: "frame",
        generation: v.generation,
        seq: f.seq,
        captureTimeUs: f.captureTimeUs,
        serverLatencyUs: f.serverLatencyUs,
        data: data.buffer,
        offset: data.byteOffset,
        length: data.length,
        positions,
      },
      transfer,
    );
  }

  /** The worker's answer for one frame. */
  function decoded(m) {
    if (m.generation !== v.generation || !state.mesh.geometry) return recycle(m.positions); // an older stream's
    if (m.type === "error") {
      recycle(m.positions);
      overlay.fail(`frame ${m.seq}: ${m.message}`);
      return;
    }
    const attr = state.mesh.geometry.getAttribute("position");
    if (m.positions.length !== attr.array.length) {
      overlay.fail(`frame ${m.seq}: ${m.positions.length / 3} vertices, the topology has ${attr.array.length / 3}`);
      return;
    }
    const old = attr.array;
    attr.array = m.positions; // the same size: three.js updates the GPU buffer in place
    recycle(old);
    v.dirty = true;
    overlay.meshFrame(m.seq, m.captureTimeUs, m.serverLatencyUs, m.length);
  }

  /** At a redraw: uploads the newest positions and computes their normals; true when it did. */
  function update() {
    if (!v.dirty) return false;
    v.dirty = false;
    const geometry = state.mesh.geometry;
    geometry.getAttribute("position").needsUpdate = true;
    geometry.computeVertexNormals();
    geometry.computeBoundingSphere();
    if (!state.mesh.framed) frameCamera(state, view);
    state.mesh.fresh = true;
    return true;
  }

  /** The socket closed: the next stream starts from its header. */
  function closed() {
    restart();
  }

  return { header, frame, update, closed };
}
