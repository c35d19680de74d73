// The vertex stream's decoder, off the main thread (issue 37): codec frames (codec.js
// decodeFrame, meshoptimizer's WASM decoder) decoded, and their vertex normals computed
// (normals.js: three.js's computeVertexNormals to the bit), in a module Worker, so that a
// detail vertex stream (150K vertices, 300K triangles a frame) cannot stall the page.
// vertex-stream.js is its only user. Messages, handled in the order sent (deltas add to the
// frame before):
//
//   in   {type: "topology", index: Uint32Array}     a new stream: its triangles; forget the lanes
//   in   {type: "reset"}                            the socket closed: forget the lanes
//   in   {type: "frame", data: ArrayBuffer, offset, length, positions, normals, ...}
//        the frame's bytes (the socket message's buffer, transferred) and positions and
//        normals buffers (Float32Array or null) lent back for reuse (transferred; used when
//        their size fits)
//   out  {type: "decoded", positions, normals, ...} both transferred
//   out  {type: "error", message, positions, normals, ...}   what was wrong; the lent buffers back
//
// Other fields of a frame message (seq, generation, ...) come back as they were. The lanes
// (u16 x 4 per vertex) never leave the worker: two buffers, the held frame's and a spare.
//
// codec.js imports meshoptimizer's decoder by a relative path (./node_modules/...), not the
// page's import map, which module workers do not see in every browser.

import { decodeFrame, ready } from "./codec.js";
import { vertexNormals } from "./normals.js";

// The worker's one state object: whether the WASM decoder is ready (messages wait in
// `backlog` until it is), the stream's index buffer, the held frame's lanes and the spare
// lanes buffer.
const decoder = { ready: false, backlog: [], index: null, lanes: null, spare: null };

self.onmessage = (e) => {
  if (decoder.ready) run(e.data);
  else decoder.backlog.push(e.data);
};

ready.then(() => {
  decoder.ready = true;
  for (const m of decoder.backlog) run(m);
  decoder.backlog.length = 0;
});

/** Handles one message in order: a new stream, a reset, or a frame (answered). */
function run(m) {
  if (m.type === "topology" || m.type === "reset") {
    decoder.index = m.type === "topology" ? m.index : null;
    decoder.lanes = decoder.spare = null;
    return;
  }
  const bytes = new Uint8Array(m.data, m.offset, m.length);
  const lent = [m.positions, m.normals];
  m.data = null;
  try {
    const d = decodeFrame(bytes, decoder.lanes, { lanes: decoder.spare, positions: m.positions });
    decoder.spare = decoder.lanes;
    decoder.lanes = d.lanes;
    const n = d.positions.length;
    const normals = m.normals && m.normals.length === n ? m.normals : new Float32Array(n);
    if (decoder.index) vertexNormals(d.positions, decoder.index, normals);
    m.type = "decoded";
    m.positions = d.positions;
    m.normals = normals;
    self.postMessage(m, [d.positions.buffer, normals.buffer]);
  } catch (err) {
    m.type = "error";
    m.message = err.message;
    self.postMessage(
      m,
      lent.filter((a) => a).map((a) => a.buffer),
    );
  }
}
