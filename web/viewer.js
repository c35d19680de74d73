// The crease viewer: subscribes to a room over WebSocket (/ws/rooms/{id}), decodes the mesh
// frames (codec.js, meshoptimizer's decoder), renders them with three.js, and lets an animator
// drag the model's control points, publishing control frames into the room (HZY11 §7, FKY08 §7:
// the keyframe interface). State for tests and curious users: `window.crease`.
//
// Two stream encodings (`?encoding=vertices|palette|auto`, default auto): vertices (every vertex
// of every frame, quantised: decoded here, normals on the CPU) and palette (issue 18: the bones
// and the detail kernel vector per frame; palette.js skins, subdivides, displaces and computes
// the normals on the GPU). auto takes palette where the renderer has float render targets
// (WebGL2 + EXT_color_buffer_float), else vertices; the overlay says which and why.
//
// A retargeting room whose markers are WebXR joints (room `hands` of the demo) offers "track my
// hands" where the browser has an immersive XR device: xr.js publishes the tracked hand's
// joints every XR frame, the hand floats in front of the user, and the overlay (on the page
// and in the headset) shows the control residual and the capture-to-mesh latency.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { decodeFrame, decodeIndices, ready } from "./codec.js";
import { PaletteSynth, floatTargetsSupported } from "./palette.js";
import { readMeshFrame, socketProtocols } from "./wire.js";
import { listTakes, startPlayer } from "./takes.js";
import { HandTracker, markerMessage, markerPlan } from "./xr.js";

const params = new URLSearchParams(location.search);
const roomId = params.get("room") || "demo";
const level = params.get("level") === "detail" ? "detail" : "base";
const encodingParam = ["vertices", "palette"].includes(params.get("encoding")) ? params.get("encoding") : "auto";

const state = {
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
  headerBytes: null, // ... and its size
  sockets: 0, // sockets opened
  rendered: 0, // requestAnimationFrame redraws that showed a new frame
  renderFps: 0, // of those, per second (over the last second)
  frameSeq: null, // the seq of the last mesh frame received
  residual: null, // the last ack's control residual, model units
  residualCapture: null, // ... and in the capture's units (retargeting rooms)
  confidence: null, // the last ack's distance from the training examples (1: their spread)
  // WebXR hands: whether the browser offers an immersive session, why not, whether tracking,
  // the hand, frames published and dropped (socket backed up), the last one's seq, and the capture-to-mesh latency
  // (ms, mean over the last half second: an XR frame's time to its mesh frame's arrival).
  xr: { supported: false, reason: "", active: false, hand: "right", tracked: false, published: 0, dropped: 0, seq: null, latencyMs: null },
  // Takes (takes.js): the room's take ids, and on a replay page (`?take=ID`) the player's
  // state (frames, duration, index sent last, t seconds, playing, speed, frames sent).
  take: { list: [], id: params.get("take"), loaded: false },
};
window.crease = state;
// Not enumerable, so JSON.stringify(window.crease) stays small: `palette` (in palette mode
// {header, frame: the raw MeshFrame messages of the header and the frame displayed, frames:
// those from the last keyframe to it, seq, readback()}) and reconnect().
const hidden = (name, value) =>
  Object.defineProperty(state, name, { value, enumerable: false, configurable: true, writable: true });
hidden("palette", null);
// The control vertices of the mesh shown (model units, model order) and the markers the hand
// tracker last published (x, y, z each), for tests.
hidden("controlPositions", () =>
  roomInfo && geometry && stream
    ? roomInfo.control_points.map((c) => vertexPosition(c.vertex, new THREE.Vector3()).toArray())
    : null,
);
hidden("xrMarkers", () => (tracker ? Array.from(tracker.markers) : null));

// ---- UI ----------------------------------------------------------------------------------
const banner = document.getElementById("banner");
const stats = document.getElementById("stats");
const tokenInput = document.getElementById("token");
const detailBox = document.getElementById("detail");
const roomSelect = document.getElementById("room");
const xrRow = document.getElementById("xr-row");
const xrButton = document.getElementById("xr");
const handSelect = document.getElementById("hand");
// The publish token: from the page's fragment (`#token=T`, which browsers never send to a
// server), else the page's query (`?token=T`: kept for old links, taken out of the address bar
// at once), else what this tab was given before. It travels in the WebSocket's subprotocols
// (wire.js socketProtocols), never in a URL.
const hashParams = new URLSearchParams(location.hash.slice(1));
const urlToken = hashParams.get("token") || params.get("token");
if (params.has("token") || hashParams.has("token")) {
  if (params.has("token")) console.warn("crease: a token in the page's query string reaches the server's logs; use #token= instead");
  params.delete("token");
  hashParams.delete("token");
  const hash = hashParams.toString();
  history.replaceState(null, "", `${location.pathname}?${params}${hash ? `#${hash}` : ""}`);
}
if (urlToken) sessionStorage.setItem(`crease-token-${roomId}`, urlToken);
tokenInput.value = urlToken || sessionStorage.getItem(`crease-token-${roomId}`) || "";
tokenInput.addEventListener("change", () => {
  sessionStorage.setItem(`crease-token-${roomId}`, tokenInput.value);
  reconnect(); // the token travels in the WebSocket's subprotocols, read at connection
});
detailBox.checked = level === "detail";
detailBox.addEventListener("change", () => {
  params.set("level", detailBox.checked ? "detail" : "base");
  location.search = params.toString();
});
roomSelect.addEventListener("change", () => {
  params.set("room", roomSelect.value);
  location.search = params.toString();
});

function showBanner(kind, text) {
  banner.className = kind || "";
  banner.textContent = text || "";
}

// ---- Scene -------------------------------------------------------------------------------
const canvas = document.getElementById("view");
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
renderer.xr.enabled = true; // draws as before until a session starts
renderer.setPixelRatio(Math.min(devicePixelRatio, 2));
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1d2025);
const camera = new THREE.PerspectiveCamera(35, 1, 0.001, 100);
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = true;
scene.add(new THREE.HemisphereLight(0xdfe8ff, 0x3a3028, 0.9));
const key = new THREE.DirectionalLight(0xffffff, 1.8);
key.position.set(1, 2, 1.5);
scene.add(key);
const rim = new THREE.DirectionalLight(0xa8c0ff, 0.7);
rim.position.set(-1.5, 0.5, -1);
scene.add(rim);
const materialParams = { color: 0xd9a58c, roughness: 0.62, metalness: 0 };
const material = new THREE.MeshStandardMaterial(materialParams);
let mesh = null;
let geometry = null;

// ---- Encoding ------------------------------------------------------------------------------
const floatTargets = floatTargetsSupported(renderer);
if (encodingParam === "vertices") {
  state.encoding = "vertices";
  state.paletteReason = "?encoding=vertices";
} else if (!floatTargets) {
  state.encoding = "vertices";
  state.paletteReason = "no float render targets";
} else {
  state.encoding = "palette";
  state.paletteReason = encodingParam === "palette" ? "GPU, ?encoding=palette" : "GPU";
}
let synth = null; // PaletteSynth, once a palette header came
let paletteMaterial = null;
let stream = null; // the current socket's encoding, from its first message
let pendingMessage = null; // the palette frame message waiting for the GPU passes
// The palette frame messages from the last keyframe on: what a decoder needs for the newest
// (window.crease.palette.frames; deltas need their bases). At most MAX_CHAIN (the server's
// keyframes come every 600 frames or fewer).
let chain = null;
const MAX_CHAIN = 4096;
let fresh = false; // a new frame since the last redraw
// The model's frame: identity on the page; in an XR session it puts the hand in front of the
// user (placeStage).
const stage = new THREE.Group();
scene.add(stage);
const handleGroup = new THREE.Group();
stage.add(handleGroup);

function resize() {
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
addEventListener("resize", resize);
resize();

// ---- The room's model: control points --------------------------------------------------
let roomInfo = null; // /api/rooms/{id}
let streamIndex = null; // model vertex -> streamed vertex
let framed = false;

async function loadRoomInfo() {
  const list = await fetch("/api/rooms").then((r) => (r.ok ? r.json() : { rooms: [] }));
  // In a cluster (crease-server --nats) the list has every room of the cluster and its owner.
  const owners = new Map((list.cluster ?? []).map((r) => [r.room, r.owner]));
  const label = (id) => (owners.has(id) ? `${id} (on ${owners.get(id)})` : id);
  roomSelect.replaceChildren(
    ...[...new Set([roomId, ...list.rooms])].map((id) => new Option(label(id), id, false, id === roomId)),
  );
  const r = await fetch(`/api/rooms/${encodeURIComponent(roomId)}`);
  if (!r.ok) throw new Error(`room ${roomId}: ${(await r.text()).trim()}`);
  roomInfo = await r.json();
  // A room that skins with dual quaternions refuses palette streams (palette.js skins linearly).
  if (roomInfo.skinning === "dqs" && state.encoding === "palette") {
    state.encoding = "vertices";
    state.paletteReason = "the room skins with dual quaternions";
  }
}

// ---- Stream ------------------------------------------------------------------------------
let ws = null;
let backoff = 500;
// The previous frame's lanes (deltas add to them), a spare lanes buffer to decode into (not the
// previous one: a delta adds to it), and the positions buffer; reused frame to frame.
let lanes = null;
let spare = null;
let positionsBuf = null;
let fpsWindow = { t: performance.now(), frames: 0, bytes: 0, latency: 0, fps: 0, bpf: 0, lat: 0 };

let socketOpened = 0;

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const q = new URLSearchParams({ level, encoding: state.encoding });
  socketOpened = performance.now();
  ws = new WebSocket(`${scheme}://${location.host}/ws/rooms/${encodeURIComponent(roomId)}?${q}`, socketProtocols(tokenInput.value));
  ws.binaryType = "arraybuffer";
  ws.onopen = () => {
    state.connected = true;
    state.sockets += 1;
    backoff = 500;
    showBanner(state.error ? "error" : "", state.error || ""); // not "disconnected" any more
  };
  ws.onmessage = (e) => {
    if (typeof e.data === "string") return onAck(JSON.parse(e.data));
    const bytes = new Uint8Array(e.data);
    let msg;
    try {
      msg = readMeshFrame(bytes);
    } catch (err) {
      state.error = `message: ${err.message}`;
      showBanner("error", state.error);
      return;
    }
    if (msg.topology) onTopology(msg.topology);
    else if (msg.paletteTopology) onPaletteTopology(msg.paletteTopology, bytes);
    else if (msg.frame && stream === "palette") onPaletteFrame(msg.frame, bytes);
    else if (msg.frame && stream === "vertices") onFrame(msg.frame);
  };
  ws.onclose = (e) => {
    state.connected = false;
    lanes = null;
    stream = null;
    const wait = backoff;
    backoff = Math.min(backoff * 2, 10000);
    showBanner("warn", `disconnected${e.reason ? `: ${e.reason}` : ""} — reconnecting in ${(wait / 1000).toFixed(1)} s`);
    setTimeout(connect, wait);
  };
}

function reconnect() {
  if (ws) {
    ws.onclose = null;
    ws.close();
  }
  state.error = null;
  showBanner();
  connect();
}
hidden("reconnect", reconnect);

/** Shows `geo` with `mat` (creating the mesh on the first header). */
function showMesh(geo, mat) {
  if (geometry && geometry !== geo) geometry.dispose();
  geometry = geo;
  if (!mesh) {
    mesh = new THREE.Mesh(geometry, mat);
    stage.add(mesh);
  } else {
    mesh.geometry = geometry;
    mesh.material = mat;
  }
}

function onTopology(t) {
  let index;
  try {
    index = decodeIndices(t.indices, t.triangleCount, t.vertexCount);
  } catch (err) {
    state.error = `topology: ${err.message}`;
    showBanner("error", state.error);
    stream = null;
    return;
  }
  stream = "vertices";
  state.headers += 1;
  if (state.encoding === "palette") {
    // A server without palette streams ignores ?encoding=palette.
    state.encoding = "vertices";
    state.paletteReason = "the server sent vertices";
  }
  hidden("palette", null);
  state.model = t.model;
  state.vertexCount = t.vertexCount;
  lanes = spare = positionsBuf = null;
  const geo = new THREE.BufferGeometry();
  geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
  geo.setIndex(new THREE.BufferAttribute(index, 1));
  showMesh(geo, material);
  mesh.frustumCulled = true;
  mesh.visible = true;
  // Control points index model vertices; the stream may be in its own order (base level).
  streamIndex = null;
  if (t.vertexOrder.length === t.vertexCount) {
    streamIndex = new Uint32Array(t.vertexCount);
    t.vertexOrder.forEach((model, i) => (streamIndex[model] = i));
  }
  buildHandles();
}

function onFrame(f) {
  let decoded;
  try {
    decoded = decodeFrame(f.data, lanes, { lanes: spare, positions: positionsBuf });
  } catch (err) {
    state.error = `frame ${f.seq}: ${err.message}`;
    showBanner("error", state.error);
    return;
  }
  spare = lanes;
  lanes = decoded.lanes;
  positionsBuf = decoded.positions;
  const attr = geometry.getAttribute("position");
  attr.array.set(decoded.positions);
  attr.needsUpdate = true;
  geometry.computeVertexNormals();
  geometry.computeBoundingSphere();
  if (!framed) frameCamera();
  fresh = true;
  onMeshFrame(f);
  state.frames += 1;
  state.bytes += f.data.length;
  fpsWindow.frames += 1;
  fpsWindow.bytes += f.data.length;
  fpsWindow.latency += f.serverLatencyUs;
}

// A palette stream's header: everything but the bones. A second one (a new socket) rebuilds.
function onPaletteTopology(t, bytes) {
  if (!synth) synth = new PaletteSynth(renderer);
  let h;
  try {
    h = synth.load(t);
  } catch (err) {
    state.error = err.message;
    showBanner("error", state.error);
    stream = null;
    if (mesh) mesh.visible = false;
    return;
  }
  stream = "palette";
  state.headers += 1;
  state.headerMs = Math.round(performance.now() - socketOpened);
  state.headerBytes = bytes.length;
  state.encoding = "palette";
  state.model = h.model;
  state.vertexCount = h.vertexCount;
  pendingMessage = null;
  chain = null;
  if (!paletteMaterial) paletteMaterial = synth.material(materialParams);
  showMesh(synth.geometry(), paletteMaterial);
  // The shader places the vertices: the header's box is the bound, no culling needed.
  mesh.frustumCulled = false;
  mesh.visible = false; // until the first frame's passes ran
  streamIndex = null; // model vertex order
  hidden("palette", { header: bytes, frame: null, frames: null, seq: null, readback: () => synth.readback() });
  buildHandles();
}

// A palette frame: decoded now (a codec frame of bone lanes, keyframe or delta), synthesised on
// the GPU at the next redraw (latest wins).
function onPaletteFrame(f, bytes) {
  let decoded;
  try {
    decoded = synth.setFrame(f.data || new Uint8Array(0));
  } catch (err) {
    state.error = `frame ${f.seq}: ${err.message}`;
    showBanner("error", state.error);
    return;
  }
  if (decoded.header.kind === 0) chain = [bytes];
  else if (chain && chain.length < MAX_CHAIN) chain.push(bytes);
  else chain = null;
  pendingMessage = { bytes, seq: f.seq, chain, length: chain ? chain.length : 0 };
  onMeshFrame(f);
  state.frames += 1;
  state.bytes += f.data.length;
  fpsWindow.frames += 1;
  fpsWindow.bytes += f.data.length;
  fpsWindow.latency += f.serverLatencyUs;
}

/** Bookkeeping common to both encodings: the seq, and an XR frame's capture-to-mesh time. */
function onMeshFrame(f) {
  state.frameSeq = f.seq;
  if (tracker && tracker.firstCaptureUs !== undefined && f.captureTimeUs >= tracker.firstCaptureUs) {
    xrWindow.latency += (performance.timeOrigin + performance.now()) / 1000 - f.captureTimeUs / 1e6;
    xrWindow.frames += 1;
  }
}

function onAck(ack) {
  state.acks += 1;
  // ABORTED (10): a newer frame of the room won while this one waited for the pipeline
  // (latest wins, the server's mailbox); the room is at the newer frame, nothing to show.
  if (ack.error && ack.error.code === 10) {
    state.superseded = (state.superseded ?? 0) + 1;
    return;
  }
  if (!ack.error) {
    state.residual = ack.control_residual;
    state.residualCapture = ack.control_residual_capture ?? null;
    state.confidence = ack.confidence ?? 0; // absent at an example
  }
  if (ack.error) {
    const bad = ack.error.code === 7;
    state.error = bad ? `publish refused: wrong or missing token` : `publish refused: ${ack.error.message}`;
    showBanner("error", state.error);
  }
}

function frameCamera() {
  // The model's rest box (every pose stays near it) rather than the first frame's pose, so the
  // framing does not depend on when the page joined; the first frame's sphere as a fallback.
  // The same at both levels and in both encodings, so the same frame looks the same.
  let center;
  let radius;
  if (roomInfo && roomInfo.bounds) {
    const [lo, hi] = roomInfo.bounds.map((v) => new THREE.Vector3(...v));
    center = lo.clone().add(hi).multiplyScalar(0.5);
    radius = hi.distanceTo(lo) / 2;
  } else {
    const s = geometry.boundingSphere;
    if (!s || !Number.isFinite(s.radius) || s.radius === 0) return;
    center = s.center;
    radius = s.radius;
  }
  controls.target.copy(center);
  camera.position.copy(center).add(new THREE.Vector3(0.2, 0.15, 1).normalize().multiplyScalar(radius * 3.6));
  camera.near = radius / 100;
  camera.far = radius * 100;
  camera.updateProjectionMatrix();
  framed = true;
}

// ---- Control-point handles and dragging -----------------------------------------------
const handleMaterial = new THREE.MeshBasicMaterial({ color: 0xffd23f, depthTest: false });
const dragMaterial = new THREE.MeshBasicMaterial({ color: 0xff5a3c, depthTest: false });
let handleMeshes = [];

function buildHandles() {
  handleGroup.clear();
  handleMeshes = [];
  if (!roomInfo || level !== "base") return; // control points index the base mesh
  const [lo, hi] = roomInfo.bounds || [[0, 0, 0], [1, 1, 1]];
  const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  const geo = new THREE.SphereGeometry(size * 0.012, 12, 8);
  for (const c of roomInfo.control_points) {
    const m = new THREE.Mesh(geo, handleMaterial);
    m.renderOrder = 10;
    m.userData = c;
    handleGroup.add(m);
    handleMeshes.push(m);
  }
}

function vertexPosition(modelVertex, out) {
  if (stream === "palette") return synth.skinVertex(modelVertex, out);
  const i = streamIndex ? streamIndex[modelVertex] : modelVertex;
  const a = geometry.getAttribute("position").array;
  return out.set(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
}

let drag = null; // {handle, plane, points: Vector3[] (the frame being posed)}
const raycaster = new THREE.Raycaster();
const pointer = new THREE.Vector2();

function toNdc(e) {
  const r = canvas.getBoundingClientRect();
  pointer.set(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
}

canvas.addEventListener("pointerdown", (e) => {
  if (!geometry || !stream || handleMeshes.length === 0) return;
  // The nearest handle within 20 px.
  let best = null;
  for (const h of state.handles) {
    const d = Math.hypot(h.x - e.clientX, h.y - e.clientY);
    if (d < 20 && (!best || d < best.d)) best = { ...h, d };
  }
  if (!best) return;
  const handle = handleMeshes.find((m) => m.userData.id === best.id);
  const points = roomInfo.control_points.map((c) => vertexPosition(c.vertex, new THREE.Vector3()));
  const normal = camera.getWorldDirection(new THREE.Vector3());
  drag = {
    handle,
    plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, handle.position),
    points,
    index: roomInfo.control_points.findIndex((c) => c.id === best.id),
  };
  handle.material = dragMaterial;
  controls.enabled = false;
  canvas.setPointerCapture(e.pointerId);
  e.preventDefault();
});

canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  toNdc(e);
  raycaster.setFromCamera(pointer, camera);
  const hit = raycaster.ray.intersectPlane(drag.plane, new THREE.Vector3());
  if (!hit) return;
  drag.points[drag.index].copy(hit);
  publish(drag.points);
});

function endDrag(e) {
  if (!drag) return;
  drag.handle.material = handleMaterial;
  drag = null;
  controls.enabled = true;
  if (e && canvas.hasPointerCapture(e.pointerId)) canvas.releasePointerCapture(e.pointerId);
}
canvas.addEventListener("pointerup", endDrag);
canvas.addEventListener("pointercancel", endDrag);

let seq = 0;
function publish(points) {
  if (!ws || ws.readyState !== WebSocket.OPEN) return;
  if (!tokenInput.value) {
    state.error = "enter the room's publish token to drag control points";
    showBanner("error", state.error);
    return;
  }
  const positions = [];
  for (const p of points) positions.push(p.x, p.y, p.z);
  ws.send(JSON.stringify({ seq: seq++, capture_time_us: Date.now() * 1000, positions }));
  state.published += 1;
}
// Publishes control points (x, y, z each, model order) as a drag would: for scripts and tests.
hidden("publish", (flat) => {
  const points = [];
  for (let i = 0; i + 2 < flat.length; i += 3) points.push({ x: flat[i], y: flat[i + 1], z: flat[i + 2] });
  publish(points);
});

/** Sends one JSON control frame as it is (a take's, takes.js); false when it cannot. */
function sendFrame(frame) {
  if (!ws || ws.readyState !== WebSocket.OPEN || !tokenInput.value) return false;
  ws.send(JSON.stringify(frame));
  state.published += 1;
  return true;
}

// ---- WebXR hands (xr.js) ----------------------------------------------------------------------
let tracker = null; // HandTracker while a session runs
let placed = false;
let xrWindow = { t: performance.now(), frames: 0, latency: 0 };
const captureUnits = () => roomInfo?.capture?.units || "capture units";

/** Publishes one XR frame's markers; false when the socket is not ready or backed up. */
function sendMarkers(captureUs, markers) {
  if (!ws || ws.readyState !== WebSocket.OPEN) return false;
  // Latest wins: a frame queued behind 64 KB would only arrive late.
  if (ws.bufferedAmount > 65536) {
    state.xr.dropped += 1;
    return false;
  }
  if (tracker.firstCaptureUs === undefined) tracker.firstCaptureUs = captureUs;
  state.xr.seq = seq;
  ws.send(markerMessage(seq++, captureUs, markers));
  state.published += 1;
  state.xr.published += 1;
  return true;
}

/** Shows "track my hands" in rooms whose markers are WebXR joints; enabled where XR is. */
async function updateXrControl() {
  xrRow.hidden = !roomInfo?.capture;
  if (xrRow.hidden) return;
  const plan = markerPlan(roomInfo.capture.markers);
  let supported = false;
  try {
    supported = Boolean(navigator.xr) && (await navigator.xr.isSessionSupported("immersive-vr"));
  } catch {
    supported = false;
  }
  state.xr.supported = supported;
  state.xr.reason = plan.error || (!navigator.xr ? "this browser has no WebXR" : supported ? "" : "no immersive XR device");
  xrButton.disabled = Boolean(state.xr.reason) && !tracker;
  xrButton.title = state.xr.reason;
}
navigator.xr?.addEventListener?.("devicechange", updateXrControl);

xrButton.addEventListener("click", async () => {
  if (tracker) return tracker.stop();
  if (!tokenInput.value) {
    state.error = "enter the room's publish token to track your hands";
    return showBanner("error", state.error);
  }
  const plan = markerPlan(roomInfo.capture.markers);
  const t = new HandTracker({ renderer, handedness: handSelect.value, plan, send: sendMarkers, onEnd: endXr });
  tracker = t;
  try {
    await t.start();
  } catch (err) {
    tracker = null;
    state.error = `WebXR: ${err.message || err}`;
    return showBanner("error", state.error);
  }
  state.xr.active = true;
  state.xr.hand = handSelect.value;
  xrButton.textContent = "stop tracking";
  handleGroup.visible = false;
  placed = false;
  scene.add(xrPanel);
});

function endXr() {
  tracker = null;
  state.xr.active = false;
  state.xr.tracked = false;
  xrButton.textContent = "track my hands";
  handleGroup.visible = true;
  stage.position.set(0, 0, 0);
  stage.quaternion.identity();
  stage.scale.setScalar(1);
  scene.remove(xrPanel);
  updateXrControl();
}

/** Puts the model 45 cm in front of where the user looked at the first XR frame, 10 cm below
 * eye level, turned to face them, about 22 cm across whatever its units. */
function placeStage() {
  if (placed || !tracker.viewer || !roomInfo?.bounds) return;
  const [lo, hi] = roomInfo.bounds.map((v) => new THREE.Vector3(...v));
  const centre = lo.clone().add(hi).multiplyScalar(0.5);
  const size = Math.max(hi.x - lo.x, hi.y - lo.y, hi.z - lo.z) || 1;
  const { position: p, orientation: o } = tracker.viewer;
  const look = new THREE.Vector3(0, 0, -1).applyQuaternion(new THREE.Quaternion(o.x, o.y, o.z, o.w));
  const yaw = Math.atan2(-look.x, -look.z);
  const forward = new THREE.Vector3(-Math.sin(yaw), 0, -Math.cos(yaw));
  const at = new THREE.Vector3(p.x, p.y - 0.1, p.z).addScaledVector(forward, 0.45);
  stage.scale.setScalar(0.22 / size);
  stage.quaternion.setFromAxisAngle(new THREE.Vector3(0, 1, 0), yaw);
  stage.position.copy(at).sub(centre.multiplyScalar(0.22 / size).applyQuaternion(stage.quaternion));
  xrPanel.position.copy(at).add(new THREE.Vector3(0, 0.17, 0));
  xrPanel.quaternion.copy(stage.quaternion);
  placed = true;
}

// The overlay inside the headset: a small text panel above the hand.
const xrCanvas = document.createElement("canvas");
xrCanvas.width = 640;
xrCanvas.height = 96;
const xrTexture = new THREE.CanvasTexture(xrCanvas);
const xrPanel = new THREE.Mesh(
  new THREE.PlaneGeometry(0.24, 0.036),
  new THREE.MeshBasicMaterial({ map: xrTexture, transparent: true, depthTest: false }),
);
xrPanel.renderOrder = 20;

/** The tracking line: the hand, the residual (mm when the capture is in metres), the latency. */
function xrText() {
  const x = state.xr;
  let res = "…";
  if (state.residualCapture != null && captureUnits() === "m") res = `${(state.residualCapture * 1000).toFixed(1)} mm`;
  else if (state.residualCapture != null) res = `${state.residualCapture.toFixed(4)} ${captureUnits()}`;
  else if (state.residual != null) res = `${state.residual.toFixed(4)} (model units)`;
  const lat = x.latencyMs == null ? "…" : `${x.latencyMs.toFixed(0)} ms`;
  const far = state.confidence > 1 ? " · outside the examples" : "";
  return `${x.hand} hand ${x.tracked ? "tracked" : "not seen"}${far}\nresidual ${res} · capture to mesh ${lat}`;
}

function drawXrPanel() {
  const g = xrCanvas.getContext("2d");
  g.clearRect(0, 0, xrCanvas.width, xrCanvas.height);
  g.fillStyle = "rgba(20, 22, 26, 0.8)";
  g.fillRect(0, 0, xrCanvas.width, xrCanvas.height);
  g.fillStyle = "#e8e8e8";
  g.font = "24px system-ui, sans-serif";
  xrText()
    .split("\n")
    .forEach((line, i) => g.fillText(line, 14, 38 + 38 * i));
  xrTexture.needsUpdate = true;
}

// ---- Render loop ---------------------------------------------------------------------------
const tmp = new THREE.Vector3();
let renderWindow = { t: performance.now(), rendered: 0 };
function render(time, frame) {
  if (frame && tracker) {
    tracker.onFrame(time, frame);
    state.xr.tracked = tracker.tracked;
    placeStage();
  }
  controls.update();
  if (stream === "palette" && synth.update()) {
    state.palette.frame = pendingMessage.bytes;
    state.palette.frames = pendingMessage.chain && pendingMessage.chain.slice(0, pendingMessage.length);
    state.palette.seq = pendingMessage.seq;
    mesh.visible = true;
    if (!framed) frameCamera();
    fresh = true;
  }
  if (fresh) {
    state.rendered += 1;
    renderWindow.rendered += 1;
    fresh = false;
  }
  if (geometry && stream && handleMeshes.length && !tracker) {
    const r = canvas.getBoundingClientRect();
    state.handles = handleMeshes.map((m, k) => {
      if (drag && drag.handle === m) m.position.copy(drag.points[drag.index]);
      else vertexPosition(roomInfo.control_points[k].vertex, m.position);
      tmp.copy(m.position).project(camera);
      return {
        id: m.userData.id,
        name: m.userData.name,
        x: r.left + ((tmp.x + 1) / 2) * r.width,
        y: r.top + ((1 - tmp.y) / 2) * r.height,
      };
    });
  }
  renderer.render(scene, camera);
  const now = performance.now();
  if (now - fpsWindow.t >= 1000) {
    const s = (now - fpsWindow.t) / 1000;
    fpsWindow.fps = fpsWindow.frames / s;
    fpsWindow.bpf = fpsWindow.bytes / Math.max(fpsWindow.frames, 1);
    fpsWindow.lat = fpsWindow.latency / Math.max(fpsWindow.frames, 1);
    fpsWindow = { ...fpsWindow, t: now, frames: 0, bytes: 0, latency: 0 };
  }
  if (now - xrWindow.t >= 500) {
    if (xrWindow.frames) state.xr.latencyMs = (1000 * xrWindow.latency) / xrWindow.frames;
    xrWindow = { t: now, frames: 0, latency: 0 };
    if (tracker) drawXrPanel();
  }
  if (now - renderWindow.t >= 1000) {
    state.renderFps = renderWindow.rendered / ((now - renderWindow.t) / 1000);
    renderWindow = { t: now, rendered: 0 };
  }
  stats.textContent =
    `model ${state.model || "…"} · ${level}\n` +
    `${state.encoding} (${state.paletteReason})\n` +
    `${state.vertexCount.toLocaleString()} vertices\n` +
    `${fpsWindow.fps.toFixed(1)} frames/s · ${Math.round(fpsWindow.bpf).toLocaleString()} B/frame\n` +
    `${state.renderFps.toFixed(1)} frames/s drawn\n` +
    `server latency ${(fpsWindow.lat / 1000).toFixed(2)} ms\n` +
    `published ${state.published} · acks ${state.acks}` +
    (state.confidence != null ? `\nconfidence ${state.confidence.toFixed(2)}${state.confidence > 1 ? " (outside the examples)" : ""}` : "") +
    (tracker ? `\n${xrText()}` : roomInfo?.capture && state.xr.reason ? `\nWebXR: ${state.xr.reason}` : "");
}

await ready;
try {
  await loadRoomInfo();
} catch (err) {
  state.error = String(err.message || err);
  showBanner("error", state.error);
}
connect();
updateXrControl();
const takeError = (msg) => {
  state.error = msg;
  showBanner("error", msg);
};
if (state.take.id) {
  startPlayer({ takeId: state.take.id, root: document.getElementById("player"), state, send: sendFrame, onError: takeError });
} else {
  listTakes({ roomId, list: document.getElementById("take-list"), state, onError: takeError }).catch((err) =>
    takeError(`takes: ${err.message || err}`),
  );
}
renderer.setAnimationLoop(render); // the window's frames, or the XR session's while one runs
