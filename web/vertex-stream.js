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

import * as THREE from "three";
import { decodeIndices } from "./codec.js";
import { frameCamera, showMesh } from "./scene.js";

/** Buffers of each kind kept to lend the worker (more in flight allocate; extras are dropped). */
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

  /** Keeps `positions` and `normals` to lend the worker again when they fit the current stream. */
  function recycle(positions, normals) {
    const n = 3 * c.vertexCount;
    if (positions && positions.length === n && v.spares.positions.length < MAX_SPARES) v.spares.positions.push(positions);
    if (normals && normals.length === n && v.spares.normals.length < MAX_SPARES) v.spares.normals.push(normals);
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
    restart(index);
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
    geo.setAttribute("normal", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
    geo.setIndex(new THREE.BufferAttribute(index, 1));
    const mesh = showMesh(state, view, geo, view.material);
    mesh.frustumCulled = true;
    mesh.visible = true;
    for (const kind of ["positions", "normals"]) v.spares[kind] = v.spares[kind].filter((a) => a.length === 3 * t.vertexCount);
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

  /** A new stream generation: results of frames sent before are dropped; the worker forgets
   * its lanes, and takes the new stream's triangles (`index`, copied: the geometry keeps it). */
  function restart(index) {
    v.generation += 1;
    if (index) worker().postMessage({ type: "topology", index });
    else if (v.worker) v.worker.postMessage({ type: "reset" });
  }

  /** A codec frame: to the worker, with the socket message's buffer (`bytes`, transferred). */
  function frame(f, bytes) {
    const data = f.data || new Uint8Array(0);
    const positions = v.spares.positions.pop() || null;
    const normals = v.spares.normals.pop() || null;
    const transfer = data.buffer === bytes.buffer ? [bytes.buffer] : [];
    if (positions) transfer.push(positions.buffer);
    if (normals) transfer.push(normals.buffer);
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
        normals,
      },
      transfer,
    );
  }

  /** The worker's answer for one frame. */
  function decoded(m) {
    if (m.generation !== v.generation || !state.mesh.geometry) return recycle(m.positions, m.normals); // an older stream's
    if (m.type === "error") {
      recycle(m.positions, m.normals);
      overlay.fail(`frame ${m.seq}: ${m.message}`);
      return;
    }
    const position = state.mesh.geometry.getAttribute("position");
    const normal = state.mesh.geometry.getAttribute("normal");
    if (m.positions.length !== position.array.length) {
      overlay.fail(`frame ${m.seq}: ${m.positions.length / 3} vertices, the topology has ${position.array.length / 3}`);
      return;
    }
    // The same sizes: three.js updates the GPU buffers in place at the upload.
    recycle(position.array, normal.array);
    position.array = m.positions;
    normal.array = m.normals;
    v.dirty = true;
    overlay.meshFrame(m.seq, m.captureTimeUs, m.serverLatencyUs, m.length);
  }

  /** At a redraw: uploads the newest positions and normals; true when it did. */
  function update() {
    if (!v.dirty) return false;
    v.dirty = false;
    const geometry = state.mesh.geometry;
    geometry.getAttribute("position").needsUpdate = true;
    geometry.getAttribute("normal").needsUpdate = true;
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
