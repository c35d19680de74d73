// The vertex stream's decoder, off the main thread (issue 37): codec frames (codec.js
// decodeFrame, meshoptimizer's WASM decoder) decoded in a module Worker so that a detail
// vertex stream (100K+ vertices a frame) cannot stall the page. vertex-stream.js is its only
// user. Messages, in order (frames are decoded in the order sent: deltas add to the frame
// before):
//
//   in   {type: "reset"}                                    forget the held lanes (a new stream)
//   in   {type: "frame", data: ArrayBuffer, offset, length, positions: Float32Array | null, ...}
//        the frame's bytes (the socket message's buffer, transferred) and a positions buffer
//        lent back for reuse (transferred; used when its size fits)
//   out  {type: "decoded", positions, ...}                  the positions (transferred)
//   out  {type: "error", message, positions, ...}           what was wrong; the lent buffer back
//
// Other fields of a frame message (seq, generation, ...) come back as they were. The lanes
// (u16 x 4 per vertex) never leave the worker: two buffers, the held frame's and a spare.
//
// codec.js imports meshoptimizer's decoder by a relative path (./node_modules/...), not the
// page's import map, which module workers do not see in every browser.

import { decodeFrame, ready } from "./codec.js";

// The worker's one state object: whether the WASM decoder is ready (messages wait in
// `backlog` until it is), the held frame's lanes and the spare lanes buffer.
const decoder = { ready: false, backlog: [], lanes: null, spare: null };

self.onmessage = (e) => {
  if (decoder.ready) run(e.data);
  else decoder.backlog.push(e.data);
};

ready.then(() => {
  decoder.ready = true;
  for (const m of decoder.backlog) run(m);
  decoder.backlog.length = 0;
});

/** Decodes one frame message (or resets) and posts the answer. */
function run(m) {
  if (m.type === "reset") {
    decoder.lanes = decoder.spare = null;
    return;
  }
  const bytes = new Uint8Array(m.data, m.offset, m.length);
  const lent = m.positions;
  m.data = null;
  try {
    const d = decodeFrame(bytes, decoder.lanes, { lanes: decoder.spare, positions: lent });
    decoder.spare = decoder.lanes;
    decoder.lanes = d.lanes;
    m.type = "decoded";
    m.positions = d.positions;
    self.postMessage(m, [d.positions.buffer]);
  } catch (err) {
    m.type = "error";
    m.message = err.message;
    self.postMessage(m, lent ? [lent.buffer] : []);
  }
}
