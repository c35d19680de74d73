// The viewer's one state object (issue 37). Everything that changes while the page runs lives
// in the object createState() makes, which the entry (viewer.js) passes to every module: the
// modules hold no mutable state of their own (constants, imports, pure functions and
// factories closing over this object, the page's elements and each other only).
//
// `state.crease` is the public part, `window.crease` (web/README.md lists its fields): what
// the browser tests and curious users read. Its functions and the palette capture are not
// enumerable, so `JSON.stringify(window.crease)` stays small. The rest is the viewer's own.

/**
 * One actor's slot (issue 38): its name, side and performer, its part of the room document
 * (`room`: control points, bounds, capture), the three.js group that places it (`group`, in
 * the stage; its handles' group `handleGroup` and its name's label inside), the mesh on screen
 * (`mesh`, `geometry`, and `streamIndex`: model vertex -> streamed vertex for base-level
 * vertex streams, or null), its vertex stream's (buffers to lend the decode worker, and
 * whether the geometry holds arrays not yet uploaded), its palette stream's (PaletteSynth,
 * its material, the frame waiting for the GPU passes, the frame messages from the last
 * keyframe on), its handles, and the last frame it drew (`seq`, `held`, `placement`).
 */
export function createActor(index) {
  return {
    index,
    name: "",
    side: null,
    performer: "",
    room: null,
    group: null,
    handleGroup: null,
    label: null,
    mesh: null,
    geometry: null,
    streamIndex: null,
    vertices: { spares: { positions: [], normals: [] }, dirty: false },
    palette: { synth: null, material: null, pending: null, chain: null },
    handles: [],
    seq: null,
    held: false,
    placement: null, // where its performer's capture puts it (ActorFrame.placement), or null
    placed: false, // whether a placement was applied since the stream began
  };
}

/** Defines a non-enumerable, writable property (assignment later keeps it hidden). */
function hidden(object, name, value) {
  Object.defineProperty(object, name, { value, enumerable: false, configurable: true, writable: true });
}

/**
 * The state of one page from its query (`params`, URLSearchParams): `?room=` (default demo),
 * `?level=detail|base`, `?encoding=vertices|palette|auto` (default auto), `?take=` (a replay
 * page's take).
 */
export function createState(params) {
  const roomId = params.get("room") || "demo";
  const level = params.get("level") === "detail" ? "detail" : "base";
  const encodingParam = ["vertices", "palette"].includes(params.get("encoding")) ? params.get("encoding") : "auto";
  const takeId = params.get("take");
  const now = performance.now();
  const crease = {
    connected: false,
    frames: 0,
    bytes: 0,
    vertexCount: 0,
    model: "",
    level,
    room: roomId,
    error: null,
    published: 0,
    acks: 0,
    handles: [],
    encoding: null, // "palette" or "vertices": what the viewer asks for and draws
    paletteReason: null, // why
    headers: 0, // stream headers received (one per socket)
    headerMs: null, // the last palette header: ms from opening its socket to the header read
    headerLoadMs: null, // ... and from the header read to its arrays decoded and set up on the GPU
    firstFrameMs: null, // ... and from opening its socket to the first redraw that showed a frame
    headerBytes: null, // ... and its size
    sockets: 0, // sockets opened
    rendered: 0, // requestAnimationFrame redraws that showed a new frame
    renderFps: 0, // of those, per second (over the last second)
    frameSeq: null, // the seq of the last mesh frame received (and decoded)
    residual: null, // the last ack's control residual, model units
    heldControls: 0, // the last ack's control points held (invalid or occluded)
    residualCapture: null, // ... and in the capture's units (retargeting rooms)
    confidence: null, // the last ack's distance from the training examples (1: their spread)
    // A room of several actors (issue 38): per actor {name, side, performer, model,
    // vertexCount, frameSeq (its last frame drawn), held, placed (where its performer's
    // capture put it), residual, residualCapture, confidence (its part of the last ack)}; one
    // entry, unnamed, in a one-actor room.
    actors: [],
    // WebXR hands: whether the browser offers an immersive session, why not, whether tracking,
    // the hand, frames published and dropped (socket backed up), the last one's seq, and the
    // capture-to-mesh latency (ms, mean over the last half second: an XR frame's time to its
    // mesh frame's arrival).
    // hands: per tracked hand {actor, hand, tracked} (two in a room of actors with sides).
    xr: { supported: false, reason: "", active: false, hand: "right", tracked: false, hands: [], published: 0, dropped: 0, seq: null, latencyMs: null },
    // The webcam source (camera-view.js): hands seen in the last frame ({side, score, image:
    // 21 [x, y] pixels}), MediaPipe's time per frame, the share of frames with a hand.
    camera: { active: false, seq: null, hands: [], lost: false, frames: 0, detected: 0, detectionRate: 0, published: 0, inferenceMs: 0, convertMs: 0 },
    // Takes (takes.js): the room's take ids, and on a replay page (`?take=ID`) the player's
    // state (frames, duration, index sent last, t seconds, playing, speed, frames sent).
    take: { list: [], id: takeId, loaded: false },
    // Batch jobs (jobs.js): the server's jobs as GET /api/jobs last listed them (while the
    // panel's "jobs" section is open).
    jobs: [],
  };
  // In palette mode {header, frame: the raw MeshFrame messages of the header and the frame
  // displayed, frames: those from the last keyframe to it, seq, readback()}; else null.
  hidden(crease, "palette", null);
  // Set by the modules that own them (viewer.js wires them): reconnect() (connection.js),
  // publish(flat, actor) (handles.js), controlPositions(actor) (handles.js), xrMarkers(actor)
  // (xr-view.js), readback(actor) (palette-stream.js: an actor's drawn mesh in palette mode).
  for (const name of ["reconnect", "publish", "controlPositions", "xrMarkers", "readback"]) hidden(crease, name, () => null);

  return {
    crease,
    params, // the page's query (URLSearchParams; panel.js takes the token out of it)
    roomId,
    level,
    encodingParam, // what the address asked for: "vertices", "palette" or "auto"
    room: null, // GET /api/rooms/{id}: control points, bounds, capture, skinning (panel.js)
    // What the current socket streams, from its first message: "vertices", "palette" or null.
    stream: null,
    // The room's actors (issue 38), one slot each (createActor): a one-actor room has one,
    // unnamed. Made as the stream's headers come (connection.js).
    actors: [],
    // The box the actors occupy as laid out (scene.js layoutActors; [min, max]), or null.
    bounds: null,
    // Whether the camera was framed on the actors, and whether a new frame came since the
    // last redraw.
    mesh: { framed: false, fresh: false },
    // The WebSocket (connection.js): the socket, the next reconnect's wait, when it was
    // opened, and the next control frame's seq (drags and XR frames share it).
    socket: { ws: null, backoff: 500, openedAt: 0, seq: 0 },
    // Vertex streams (vertex-stream.js): the decode worker (every actor's), and the stream's
    // generation (a new stream or socket starts one: older results are dropped).
    vertices: { worker: null, generation: 0 },
    // Control-point handles (handles.js): the drag in progress.
    handles: { drag: null },
    // WebXR (xr-view.js): the HandTracker while a session runs, whether the stage was placed.
    xr: { tracker: null, placed: false },
    // Rates for the overlay (overlay.js): mesh frames (1 s windows), XR latency (0.5 s), redraws.
    rates: {
      frames: { t: now, frames: 0, bytes: 0, latency: 0, fps: 0, bpf: 0, lat: 0 },
      xr: { t: now, frames: 0, latency: 0 },
      render: { t: now, rendered: 0 },
    },
  };
}
