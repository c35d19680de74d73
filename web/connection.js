// The connection (issue 37): the room's WebSocket (/ws/rooms/{id}?level=&encoding=, the
// publish token in its subprotocols: wire.js socketProtocols), its reconnects with backoff,
// the binary MeshFrame messages handed to the stream that owns them, the JSON acks of what
// this page published, and sending control frames. The one place that knows the wire's
// status codes, by name (`Code`: gRPC's, which the acks carry).
//
// A room of several actors (issue 38) sends one header per actor, in the room's order, each
// naming its actor and how many there are: the first makes the actors' slots (state.js
// createActor, each with its part of the room document), and the last finishes the stream
// (`onHeader`: the layout and the handles). Each frame then holds every actor's frame of one
// instant (`Frame.actors`), handed to each actor's stream.

import { removeActor } from "./scene.js";
import { createActor } from "./state.js";
import { readMeshFrame, socketProtocols } from "./wire.js";

/** gRPC status codes (google.rpc.Code), as the server's acks carry them (`ack.error.code`). */
export const Code = Object.freeze({
  OK: 0,
  CANCELLED: 1,
  UNKNOWN: 2,
  INVALID_ARGUMENT: 3,
  DEADLINE_EXCEEDED: 4,
  NOT_FOUND: 5,
  ALREADY_EXISTS: 6,
  PERMISSION_DENIED: 7,
  RESOURCE_EXHAUSTED: 8,
  FAILED_PRECONDITION: 9,
  ABORTED: 10,
  OUT_OF_RANGE: 11,
  UNIMPLEMENTED: 12,
  INTERNAL: 13,
  UNAVAILABLE: 14,
  DATA_LOSS: 15,
  UNAUTHENTICATED: 16,
});

/** The first reconnect's wait and the longest (ms): doubled per failed try. */
const BACKOFF_MS = 500;
const MAX_BACKOFF_MS = 10000;
/** A socket with more than this queued is backed up (XR frames are dropped, latest wins). */
const BACKED_UP_BYTES = 65536;

/**
 * The room's socket. `token()` reads the publish token; `streams` = {vertices, palette} (their
 * header(slot, t, bytes) for one actor's slot, true when it began its stream; frame(f,
 * bytes) for every actor's frame of a message; closed()); `onHeader()`
 * runs after a stream began; `overlay` for the banner.
 * Returns {connect, reconnect, ready, backedUp, send}.
 */
export function createConnection(state, { token, streams, onHeader, overlay }) {
  const c = state.crease;
  const sock = state.socket;

  function onMessage(e) {
    if (typeof e.data === "string") return onAck(JSON.parse(e.data));
    const bytes = new Uint8Array(e.data);
    let msg;
    try {
      msg = readMeshFrame(bytes);
    } catch (err) {
      return overlay.fail(`message: ${err.message}`);
    }
    const header = msg.topology ? ["vertices", msg.topology] : msg.paletteTopology ? ["palette", msg.paletteTopology] : null;
    if (header) {
      const [kind, t] = header;
      const slot = actorSlot(t);
      if (slot && streams[kind].header(slot, t, bytes) && t.actorIndex + 1 >= t.actorCount) {
        c.model = state.actors.map((a) => a.model).join(", ");
        c.vertexCount = state.actors.reduce((n, a) => n + (a.vertexCount || 0), 0);
        c.actors = state.actors.map((a) => ({
          name: a.name, side: a.side, performer: a.performer, model: a.model, vertexCount: a.vertexCount,
          frameSeq: null, held: false, placed: false, residual: null, residualCapture: null, confidence: null,
        }));
        onHeader();
      }
      return;
    }
    if (msg.frame && state.stream) streams[state.stream].frame(msg.frame, bytes);
  }

  /** The slot of the actor a header is for (the first header of a stream makes the slots), or
   * null (on the banner) when the header does not fit the stream. */
  function actorSlot(t) {
    const count = Math.max(1, t.actorCount);
    if (t.actorIndex >= count || (t.actorIndex > 0 && state.actors.length !== count)) {
      overlay.fail(`header of actor ${t.actorIndex} (${JSON.stringify(t.actor)}) of ${count}, after ${state.actors.length}`);
      return null;
    }
    if (t.actorIndex === 0) {
      for (const gone of state.actors.splice(count)) removeActor(gone);
      while (state.actors.length < count) state.actors.push(createActor(state.actors.length));
      for (const a of state.actors) a.placed = false;
      state.mesh.framed = false;
    }
    const slot = state.actors[t.actorIndex];
    slot.name = t.actor;
    // The room document's part for the actor (GET /api/rooms/{id}: `actors`, in this order).
    const doc = t.actorCount > 0 ? state.room?.actors?.[t.actorIndex] : state.room;
    if (t.actorCount > 0 && doc && doc.name !== t.actor) {
      overlay.fail(`the stream's actor ${t.actorIndex} is ${JSON.stringify(t.actor)}, the room's is ${JSON.stringify(doc.name)} (reload the page)`);
    }
    slot.room = doc ?? null;
    slot.side = doc?.side ?? null;
    slot.performer = doc?.performer ?? "";
    return slot;
  }

  function onAck(ack) {
    c.acks += 1;
    const code = ack.error ? ack.error.code : Code.OK;
    // ABORTED: a newer frame of the room won while this one waited for the pipeline (latest
    // wins, the server's mailbox); the room is at the newer frame, nothing to show.
    if (code === Code.ABORTED) {
      c.superseded = (c.superseded ?? 0) + 1;
      return;
    }
    if (!ack.error) {
      c.residual = ack.control_residual;
      c.residualCapture = ack.control_residual_capture ?? null;
      c.confidence = ack.confidence ?? 0; // absent at an example
      c.heldControls = ack.held_controls ?? 0; // invalid or occluded this frame
      for (const part of ack.actors ?? []) {
        const a = c.actors.find((x) => x.name === part.actor);
        if (!a) continue;
        a.residual = part.control_residual;
        a.residualCapture = part.control_residual_capture ?? null;
        a.confidence = part.confidence ?? 0;
      }
      return;
    }
    overlay.fail(
      code === Code.PERMISSION_DENIED ? "publish refused: wrong or missing token" : `publish refused: ${ack.error.message}`,
    );
  }

  function connect() {
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    const q = new URLSearchParams({ level: state.level, encoding: c.encoding });
    sock.openedAt = performance.now();
    const ws = new WebSocket(`${scheme}://${location.host}/ws/rooms/${encodeURIComponent(state.roomId)}?${q}`, socketProtocols(token()));
    sock.ws = ws;
    ws.binaryType = "arraybuffer";
    ws.onopen = () => {
      c.connected = true;
      c.sockets += 1;
      sock.backoff = BACKOFF_MS;
      overlay.showBanner(c.error ? "error" : "", c.error || ""); // not "disconnected" any more
    };
    ws.onmessage = onMessage;
    ws.onclose = (e) => {
      c.connected = false;
      streams.vertices.closed();
      streams.palette.closed();
      state.stream = null;
      const wait = sock.backoff;
      sock.backoff = Math.min(sock.backoff * 2, MAX_BACKOFF_MS);
      overlay.showBanner("warn", `disconnected${e.reason ? `: ${e.reason}` : ""} — reconnecting in ${(wait / 1000).toFixed(1)} s`);
      setTimeout(connect, wait);
    };
  }

  function reconnect() {
    if (sock.ws) {
      sock.ws.onclose = null;
      sock.ws.close();
    }
    c.error = null;
    overlay.showBanner();
    connect();
  }

  /** Whether the socket is open. */
  const ready = () => Boolean(sock.ws) && sock.ws.readyState === WebSocket.OPEN;
  /** Whether more than 64 KB wait to be sent (a frame queued behind them would arrive late). */
  const backedUp = () => sock.ws.bufferedAmount > BACKED_UP_BYTES;
  /** Sends one text message (a JSON control frame); false when the socket is not open. */
  function send(text) {
    if (!ready()) return false;
    sock.ws.send(text);
    return true;
  }

  return { connect, reconnect, ready, backedUp, send };
}
