// The vertex stream's decoder, off the main thread (issue 37): codec frames (codec.js
// decodeFrame, meshoptimizer's WASM decoder) decoded, and their vertex normals computed
// (normals.js: three.js's computeVertexNormals to the bit), in a module Worker, so that a
// detail vertex stream (150K vertices, 300K triangles a frame) cannot stall the page.
// vertex-stream.js is its only user. A room of several actors (issue 38) streams an actor's
// frame each per message: the worker keeps each actor's triangles and lanes, decodes every
// actor's part of a message and answers them together, so the page swaps in one instant's
// meshes of every actor at once. Messages, handled in the order sent (deltas add to the frame
// before):
//
//   in   {type: "topology", actor, index: Uint32Array}   actor's stream: its triangles; forget its lanes
//   in   {type: "reset"}                                  a new stream or socket: forget every actor
//   in   {type: "frame", data: ArrayBuffer, parts: [{actor, offset, length, positions, normals}], ...}
//        the message's bytes (the socket message's buffer, transferred) and per actor its
//        frame's place in them and positions and normals buffers (Float32Array or null) lent
//        back for reuse (transferred; used when their size fits)
//   out  {type: "decoded", parts: [{actor, positions, normals, length}], ...}  both transferred
//   out  {type: "error", message, parts, ...}   what was wrong; the lent buffers back
//
// Other fields of a frame message (seq, generation, ...) come back as they were. The lanes
// (u16 x 4 per vertex) never leave the worker: per actor two buffers, the held frame's and a
// spare.
//
// codec.js imports meshoptimizer's decoder by a relative path (./node_modules/...), not the
// page's import map, which module workers do not see in every browser.

import { decodeFrame, ready } from "./codec.js";
import { vertexNormals } from "./normals.js";

// The worker's one state object: whether the WASM decoder is ready (messages wait in
// `backlog` until it is), and per actor its stream's index buffer, its held frame's lanes and
// its spare lanes buffer.
const decoder = { ready: false, backlog: [], actors: [] };

self.onmessage = (e) => {
  if (decoder.ready) run(e.data);
  else decoder.backlog.push(e.data);
};

ready.then(() => {
  decoder.ready = true;
  for (const m of decoder.backlog) run(m);
  decoder.backlog.length = 0;
});

/** Decodes one actor's part of a frame message in place (its positions and normals). */
function decodePart(data, part) {
  const a = decoder.actors[part.actor];
  if (!a) throw new Error(`actor ${part.actor} has no topology`);
  const bytes = new Uint8Array(data, part.offset, part.length);
  const d = decodeFrame(bytes, a.lanes, { lanes: a.spare, positions: part.positions });
  a.spare = a.lanes;
  a.lanes = d.lanes;
  const n = d.positions.length;
  const normals = part.normals && part.normals.length === n ? part.normals : new Float32Array(n);
  if (a.index) vertexNormals(d.positions, a.index, normals);
  part.positions = d.positions;
  part.normals = normals;
}

/** The buffers of `parts` to transfer back. */
const buffers = (parts) => parts.flatMap((p) => [p.positions, p.normals]).filter((a) => a).map((a) => a.buffer);

/** Handles one message in order: an actor's stream, a reset, or a frame (answered). */
function run(m) {
  if (m.type === "reset") {
    decoder.actors = [];
    return;
  }
  if (m.type === "topology") {
    decoder.actors[m.actor] = { index: m.index, lanes: null, spare: null };
    return;
  }
  const data = m.data;
  m.data = null;
  try {
    for (const part of m.parts) decodePart(data, part);
    m.type = "decoded";
    self.postMessage(m, buffers(m.parts));
  } catch (err) {
    m.type = "error";
    m.message = err.message;
    self.postMessage(m, buffers(m.parts));
  }
}
